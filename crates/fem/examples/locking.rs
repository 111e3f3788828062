//! Prints the README's locking table: tip deflection of a 10 × 1 × 1 cantilever
//! over Timoshenko beam theory, per element, formulation and Poisson's ratio.
//!
//! cargo run --release -p augsim-fem --example locking [-- nx ny nz]

use augsim_fem::verification::cantilever_deflection_ratio;
use augsim_fem::{Formulation, Law};
use mesh::CellKind;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args().skip(1).map(|a| a.parse()).collect::<Result<_, _>>()?;
    let cells = if args.len() == 3 { [args[0], args[1], args[2]] } else { [40, 4, 4] };
    let poisson = [0.3, 0.45, 0.49, 0.499];
    println!(
        "Cantilever 10 x 1 x 1, {}x{}x{} cells, linear law: tip deflection / Timoshenko",
        cells[0], cells[1], cells[2]
    );
    println!();
    println!("| element | formulation | {} |", poisson.map(|nu| format!("ν = {nu}")).join(" | "));
    println!("| --- | --- |{}", " --- |".repeat(poisson.len()));
    for kind in [CellKind::Tet4, CellKind::Tet10, CellKind::Hex8] {
        for (form, label) in [(Formulation::Standard, "standard"), (Formulation::Fbar, "F-bar")] {
            let ratios: Vec<String> = poisson
                .iter()
                .map(|&nu| cantilever_deflection_ratio(kind, cells, Law::Linear, form, nu).map(|r| format!("{r:.3}")))
                .collect::<Result<_, _>>()?;
            println!("| {} | {label} | {} |", kind.name(), ratios.join(" | "));
        }
    }
    Ok(())
}
