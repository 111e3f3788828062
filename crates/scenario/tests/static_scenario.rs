//! Static scenarios build the problems they describe.

use std::path::Path;

use augsim_scenario::StaticScenario;

/// `[[attachment]]` and `[[patch_force]]` on the phantom's balls: point springs holding the
/// attachment, nodal forces summing to the total; a region given twice or not at all, and a
/// region the phantom has no ball for, are clear errors.
#[test]
fn geometric_attachments_and_patch_forces_build_and_bad_ones_are_named() {
    let text = |region: &str| {
        format!(
            "kind = \"static\"\nname = \"g\"\n[mesh.phantom]\ntets = 800\n[material]\nlaw = \"linear\"\n\
             young = 5000.0\npoisson = 0.45\n[[attachment]]\n{region}\nstiffness = 5.0e8\n[[patch_force]]\n\
             phantom = \"push\"\ntotal = [0.0, 0.0, -0.3]\n"
        )
    };
    let build = |region: &str| {
        let s = StaticScenario::parse(&text(region), Path::new("g.toml"))?;
        s.build_problem(Path::new("."))
    };
    let p = build("phantom = \"fixed\"").unwrap();
    assert!(p.point_springs.len() > 100 && p.dirichlet.is_empty());
    let fz: f64 = p.f_ext.iter().skip(2).step_by(3).sum();
    assert!((fz + 0.3).abs() < 1e-12, "{fz}");
    // Only the visible side of the push patch is loaded.
    let loaded = (0..p.mesh.num_nodes()).filter(|&n| p.f_ext[3 * n + 2] != 0.0);
    assert!(loaded.clone().all(|n| p.mesh.nodes[n][2] > 0.0), "the push patch is on top");
    assert!(build("ball = { centre = [-0.015, 0.0, -0.03], radius = 0.03 }").is_ok());
    let e = |region: &str| build(region).unwrap_err().to_string();
    assert!(e("").contains("give either"), "{}", e(""));
    let both = "phantom = \"fixed\"\nball = { centre = [0.0, 0.0, 0.0], radius = 0.01 }";
    assert!(e(both).contains("give either"), "{}", e(both));
    assert!(e("phantom = \"liver\"").contains("no ball behind region 'liver'"), "{}", e("phantom = \"liver\""));
    let far = "ball = { centre = [1.0, 1.0, 1.0], radius = 0.01 }";
    assert!(e(far).contains("attachment 1") && e(far).contains("no part of the mesh"), "{}", e(far));
}
