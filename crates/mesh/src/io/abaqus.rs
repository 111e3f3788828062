//! Abaqus and CalculiX input decks (`.inp`): the mesh and its node and element sets ([`read_inp`]).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use super::text::{Line, LineReader};
use super::{finish_volume, read_bytes, VolumeKind};
use crate::{Mesh, MeshError};

/// How deep `*INCLUDE`s may nest (a file that includes itself stops there).
const MAX_INCLUDE_DEPTH: usize = 16;

/// A line of a deck, for error messages: an index into `Deck::files` and a line number.
#[derive(Clone, Copy, Debug)]
struct Place {
    file: usize,
    line: usize,
}

/// A member of a set's list: a number, or another set by its upper-case name.
#[derive(Clone, Debug)]
enum Member {
    Number(u64),
    Set(String),
}

/// A node or element set: its name as first written and its members with their lines.
#[derive(Default)]
struct Set {
    name: String,
    members: Vec<(Member, Place)>,
    /// Element sets (upper case) whose elements' nodes belong to this node set (`*NSET, ELSET=`).
    element_sets: Vec<String>,
}

/// An element as read: its solid kind (`None` for an element that makes no cell) and node numbers.
struct Element {
    kind: Option<VolumeKind>,
    nodes: Vec<u64>,
    place: Place,
}

/// What the data lines under the current keyword are.
enum Block {
    Nodes { set: Option<String> },
    Elements { kind: Option<VolumeKind>, set: Option<String> },
    NodeSet { name: String, generate: bool },
    ElementSet { name: String, generate: bool },
    Instance,
    Skip,
}

/// Everything read from a deck and its includes.
#[derive(Default)]
struct Deck {
    files: Vec<PathBuf>,
    coords: Vec<[f64; 3]>,
    node_numbers: Vec<usize>,
    node_index: HashMap<u64, usize>,
    elements: Vec<(u64, Element)>,
    element_index: HashMap<u64, usize>,
    /// Node and element sets by upper-case name.
    node_sets: HashMap<String, Set>,
    element_sets: HashMap<String, Set>,
    /// The order in which sets were first named: (a node set, upper-case name).
    set_order: Vec<(bool, String)>,
    parts: usize,
}
/// The keyword of a keyword line (upper case, without `*`) and its parameters (upper-case keys,
/// values as written; a parameter without `=` has an empty value).
fn keyword(text: &str) -> (String, Vec<(String, String)>) {
    let mut fields = text.trim_start().trim_start_matches('*').split(',');
    let name = fields.next().unwrap_or("").trim().to_uppercase();
    let params = fields
        .map(str::trim)
        .filter(|f| !f.is_empty())
        .map(|f| match f.split_once('=') {
            Some((k, v)) => (k.trim().to_uppercase(), v.trim().trim_matches('"').to_string()),
            None => (f.to_uppercase(), String::new()),
        })
        .collect();
    (name, params)
}

fn param<'a>(params: &'a [(String, String)], key: &str) -> Option<&'a str> {
    params.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
}

/// The comma-separated entries of a data line, blank ones (a trailing comma) left out.
fn entries(text: &str) -> Vec<&str> {
    text.split(',').map(str::trim).filter(|e| !e.is_empty()).collect()
}

/// A positive integer entry (node or element number).
fn number(line: &Line, entry: &str, what: &str) -> Result<u64, MeshError> {
    match entry.parse::<u64>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(line.error(format!("expected {what} (a positive integer), found '{entry}'"))),
    }
}

/// A real entry; Fortran's `D` exponent is read as `E`.
fn real(line: &Line, entry: &str) -> Result<f64, MeshError> {
    let x: f64 = entry
        .replace(['d', 'D'], "E")
        .parse()
        .map_err(|_| line.error(format!("expected a coordinate, found '{entry}'")))?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(line.error(format!("coordinate '{entry}' is not finite")))
    }
}

/// The kind of a solid element type, `Ok(None)` for a type that makes no cell, or an error for a
/// solid type augsim has no cell for.
fn element_kind(line: &Line, ty: &str) -> Result<Option<VolumeKind>, MeshError> {
    let Some(rest) = ty.strip_prefix("C3D") else { return Ok(None) };
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    match digits.as_str() {
        "4" => Ok(Some(VolumeKind::Tet)),
        "10" => Ok(Some(VolumeKind::Tet10)),
        "8" => Ok(Some(VolumeKind::Hex)),
        _ => Err(line.error(format!(
            "element type {ty}: only the solids C3D4, C3D10 and C3D8 (and their variants, e.g. C3D10M, C3D8R) \
             are supported"
        ))),
    }
}

impl Deck {
    /// An error located at `place`.
    fn error(&self, place: Place, message: impl std::fmt::Display) -> MeshError {
        MeshError::parse(&self.files[place.file], format!("line {}: {message}", place.line))
    }

    /// The set named `name` (any case) of nodes or of elements, created at its first mention.
    fn set(&mut self, nodes: bool, name: &str) -> &mut Set {
        let key = name.to_uppercase();
        let sets = if nodes { &mut self.node_sets } else { &mut self.element_sets };
        sets.entry(key.clone()).or_insert_with(|| {
            self.set_order.push((nodes, key));
            Set { name: name.to_string(), ..Set::default() }
        })
    }

    /// Reads `path` and the files it includes, `depth` includes deep.
    fn read_file(&mut self, path: &Path, depth: usize) -> Result<(), MeshError> {
        let bytes = read_bytes(path)?;
        let text = String::from_utf8_lossy(&bytes);
        self.files.push(path.to_path_buf());
        let file = self.files.len() - 1;
        let mut lines = LineReader::new(path, &text);
        let mut block = Block::Skip;
        // An element whose entries go on on the next line: its number and node numbers so far.
        let mut pending: Option<(u64, Vec<u64>, Place)> = None;
        while let Some(line) = lines.next_line() {
            let text = line.text.trim();
            if text.starts_with("**") {
                continue;
            }
            let place = Place { file, line: line.no };
            if text.starts_with('*') {
                if let Some((n, _, at)) = pending.take() {
                    return Err(self.error(at, format!("element {n} lists too few nodes for its type")));
                }
                block = self.keyword_line(&line, path, depth)?;
                continue;
            }
            let e = entries(text);
            match &block {
                Block::Skip => {}
                Block::Instance => {
                    return Err(line.error(
                        "an *INSTANCE placed by a translation or rotation: write the deck without parts and \
                         assemblies (a flat input file)",
                    ))
                }
                Block::Nodes { set } => {
                    let n = number(&line, e.first().copied().unwrap_or(""), "a node number")?;
                    if e.len() > 4 {
                        return Err(line.error(format!("node {n} has {} coordinates, expected at most 3", e.len() - 1)));
                    }
                    let mut p = [0.0; 3];
                    for (x, entry) in p.iter_mut().zip(&e[1..]) {
                        *x = real(&line, entry)?;
                    }
                    if self.node_index.insert(n, self.coords.len()).is_some() {
                        return Err(line.error(format!("node {n} is defined twice")));
                    }
                    self.coords.push(p);
                    self.node_numbers.push(n as usize);
                    if let Some(set) = set {
                        self.set(true, set).members.push((Member::Number(n), place));
                    }
                }
                Block::Elements { kind, set } => {
                    let kind = *kind;
                    let (n, mut nodes, at, listed) = match pending.take() {
                        Some((n, nodes, at)) => (n, nodes, at, &e[..]),
                        None => (
                            number(&line, e.first().copied().unwrap_or(""), "an element number")?,
                            Vec::new(),
                            place,
                            &e[e.len().min(1)..],
                        ),
                    };
                    for entry in listed {
                        nodes.push(number(&line, entry, "a node number")?);
                    }
                    let more = match kind.map(VolumeKind::nodes) {
                        Some(count) if nodes.len() > count => {
                            return Err(
                                line.error(format!("element {n} lists {} nodes, its type has {count}", nodes.len()))
                            )
                        }
                        Some(count) => nodes.len() < count,
                        None => text.ends_with(','),
                    };
                    if more {
                        pending = Some((n, nodes, at));
                        continue;
                    }
                    if self.element_index.insert(n, self.elements.len()).is_some() {
                        return Err(line.error(format!("element {n} is defined twice")));
                    }
                    self.elements.push((n, Element { kind, nodes, place: at }));
                    if let Some(set) = set {
                        self.set(false, set).members.push((Member::Number(n), at));
                    }
                }
                Block::NodeSet { name, generate } | Block::ElementSet { name, generate } => {
                    let members = if *generate { generated(&line, &e)? } else { listed(&line, &e)? };
                    let set = self.set(matches!(block, Block::NodeSet { .. }), name);
                    set.members.extend(members.into_iter().map(|m| (m, place)));
                }
            }
        }
        match pending {
            Some((n, _, at)) => {
                Err(self.error(at, format!("element {n} lists too few nodes for its type (the file ends)")))
            }
            None => Ok(()),
        }
    }

    /// Acts on a keyword line of the file `path` and returns what its data lines are.
    fn keyword_line(&mut self, line: &Line, path: &Path, depth: usize) -> Result<Block, MeshError> {
        let (name, params) = keyword(line.text);
        let set_name = |key: &str| -> Result<Option<String>, MeshError> {
            match param(&params, key) {
                Some("") => Err(line.error(format!("*{name} has an empty {key}="))),
                other => Ok(other.map(str::to_string)),
            }
        };
        Ok(match name.as_str() {
            "NODE" => {
                if let Some(system) = param(&params, "SYSTEM").filter(|s| !s.eq_ignore_ascii_case("R")) {
                    return Err(line.error(format!(
                        "*NODE in coordinate system {system}: only rectangular coordinates (SYSTEM=R) are read"
                    )));
                }
                Block::Nodes { set: set_name("NSET")? }
            }
            "ELEMENT" => {
                let ty = param(&params, "TYPE").ok_or_else(|| line.error("*ELEMENT without TYPE="))?.to_uppercase();
                Block::Elements { kind: element_kind(line, &ty)?, set: set_name("ELSET")? }
            }
            "NSET" | "ELSET" => {
                let nodes = name == "NSET";
                let set = set_name(&name)?.ok_or_else(|| line.error(format!("*{name} without {name}=")))?;
                self.set(nodes, &set);
                let generate = params.iter().any(|(k, _)| k == "GENERATE");
                match (nodes, set_name("ELSET")?) {
                    (true, Some(elements)) => {
                        self.set(false, &elements);
                        self.set(true, &set).element_sets.push(elements.to_uppercase());
                        Block::Skip
                    }
                    (true, None) => Block::NodeSet { name: set, generate },
                    (false, _) => Block::ElementSet { name: set, generate },
                }
            }
            "INCLUDE" => {
                let input = set_name("INPUT")?.ok_or_else(|| line.error("*INCLUDE without INPUT="))?;
                if depth >= MAX_INCLUDE_DEPTH {
                    return Err(line.error(format!(
                        "*INCLUDE nested more than {MAX_INCLUDE_DEPTH} deep (does a file include itself?)"
                    )));
                }
                let file = path.parent().unwrap_or(Path::new("")).join(&input);
                self.read_file(&file, depth + 1).map_err(|e| match e {
                    MeshError::Io { .. } => line.error(format!("*INCLUDE: {e}")),
                    other => other,
                })?;
                Block::Skip
            }
            "PART" => {
                self.parts += 1;
                if self.parts > 1 {
                    return Err(line.error(
                        "a second *PART: augsim reads one mesh; write the deck without parts and assemblies \
                         (a flat input file) or keep one part",
                    ));
                }
                Block::Skip
            }
            "INSTANCE" => Block::Instance,
            _ => Block::Skip,
        })
    }

    /// The numbers a set holds, with the line of each, through the sets it names (a set named
    /// again inside itself adds nothing more).
    fn resolve(
        &self,
        nodes: bool,
        key: &str,
        seen: &mut HashSet<(bool, String)>,
    ) -> Result<Vec<(u64, Place)>, MeshError> {
        let sets = if nodes { &self.node_sets } else { &self.element_sets };
        let set = &sets[key];
        if !seen.insert((nodes, key.to_string())) {
            return Ok(Vec::new());
        }
        let mut numbers = Vec::new();
        for (member, place) in &set.members {
            match member {
                Member::Number(k) => numbers.push((*k, *place)),
                Member::Set(other) if sets.contains_key(other) => numbers.extend(self.resolve(nodes, other, seen)?),
                Member::Set(other) => {
                    let kind = if nodes { "node" } else { "element" };
                    return Err(self.error(
                        *place,
                        format!("set {} names {other}, which is not a {kind} set of the deck", set.name),
                    ));
                }
            }
        }
        for elements in &set.element_sets {
            for (k, place) in self.resolve(false, elements, seen)? {
                numbers.extend(self.element(k, place, &set.name)?.nodes.iter().map(|&n| (n, place)));
            }
        }
        Ok(numbers)
    }

    /// Element `k`, named in set `set` at `place`.
    fn element(&self, k: u64, place: Place, set: &str) -> Result<&Element, MeshError> {
        match self.element_index.get(&k) {
            Some(&i) => Ok(&self.elements[i].1),
            None => Err(self.error(place, format!("set {set} names element {k}, which no *ELEMENT defines"))),
        }
    }

    /// The index of node `n`, named by `what` at `place`.
    fn node(&self, n: u64, place: Place, what: &str) -> Result<usize, MeshError> {
        match self.node_index.get(&n) {
            Some(&i) => Ok(i),
            None => Err(self.error(place, format!("{what} names node {n}, which no *NODE defines"))),
        }
    }
}

/// The members of a `GENERATE` line: first, last[, increment].
fn generated(line: &Line, e: &[&str]) -> Result<Vec<Member>, MeshError> {
    let what = "a number of the GENERATE range";
    if !(2..=3).contains(&e.len()) {
        return Err(line.error("a GENERATE line is: first, last[, increment]"));
    }
    let (a, b) = (number(line, e[0], what)?, number(line, e[1], what)?);
    let step = if e.len() == 3 { number(line, e[2], what)? } else { 1 };
    if b < a || (b - a) / step > 100_000_000 {
        return Err(line.error(format!("GENERATE range {a} to {b} by {step} is empty or too long")));
    }
    Ok((a..=b).step_by(step as usize).map(Member::Number).collect())
}

/// The members of a set's data line: numbers and set names.
fn listed(line: &Line, e: &[&str]) -> Result<Vec<Member>, MeshError> {
    e.iter()
        .map(|entry| match entry.parse::<u64>() {
            Ok(k) if k > 0 => Ok(Member::Number(k)),
            _ if entry.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') => {
                Ok(Member::Set(entry.to_uppercase()))
            }
            _ => Err(line.error(format!("expected a positive number or a set name, found '{entry}'"))),
        })
        .collect()
}

/// Reads the mesh of an Abaqus or CalculiX input deck, its sets as regions.
///
/// Read: `*NODE` (rectangular coordinates; missing ones are 0, as Abaqus reads them), `*ELEMENT`
/// of the solid types C3D4, C3D10 and C3D8 and their variants (C3D4H, C3D10M, C3D8R, C3D8I…:
/// the mesh only; the scenario's formulation decides the integration, so a C3D8R deck solves as
/// full-integration hexahedra, stiffer than CalculiX's reduced integration), whose node orders are
/// VTK's, `*NSET` and `*ELSET` (lists of numbers and of sets named before or
/// after, `GENERATE` ranges, `*NSET, ELSET=` for the nodes of an element set), the `NSET=` and
/// `ELSET=` of `*NODE` and `*ELEMENT`, and `*INCLUDE` (a path relative to the including file's
/// directory, as CalculiX decks made by cgx use it). Other elements (shells, beams, springs) make
/// no cell but their nodes count in element sets. Every other keyword (materials, sections,
/// steps, boundary conditions, loads) is skipped with its data lines: the loads are a scenario's.
/// Keywords, parameters and set names are case-insensitive, as in Abaqus; a region keeps its set's
/// spelling where first defined.
///
/// Regions: every node set, and every element set as the nodes of its elements (a node set and
/// an element set of the same name add up); an element set that holds every solid element is the
/// whole mesh, not a region. Node numbers are the file's: [`Mesh::file_nodes`] keeps them, so
/// that `list` selections take them. Other solid elements (C3D6, C3D15, C3D20…) are refused; so
/// are decks with several `*PART`s or an `*INSTANCE` placed by a translation or rotation.
pub fn read_inp(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    let path = path.as_ref();
    let mut deck = Deck::default();
    deck.read_file(path, 0)?;
    if deck.coords.is_empty() {
        return Err(MeshError::parse(path, "no *NODE lines: not a mesh"));
    }
    let mut kind: Option<(VolumeKind, Place)> = None;
    let (mut conn, mut solids) = (Vec::new(), Vec::new());
    for (n, element) in &deck.elements {
        let Some(k) = element.kind else { continue };
        match kind {
            None => kind = Some((k, element.place)),
            Some((first, at)) if first != k => {
                let first_at = format!("{} line {}", deck.files[at.file].display(), at.line);
                return Err(deck.error(
                    element.place,
                    format!(
                        "element {n}: the deck mixes {} (first at {first_at}) and {}; a mesh holds one kind of cell",
                        first.plural(),
                        k.plural()
                    ),
                ));
            }
            Some(_) => {}
        }
        for &node in &element.nodes {
            conn.push(deck.node(node, element.place, &format!("element {n}"))?);
        }
        solids.push(*n as usize);
    }
    let Some((kind, _)) = kind else {
        return Err(MeshError::parse(path, "no solid elements (C3D4, C3D10 or C3D8): not a volume mesh"));
    };
    let describe = |i: usize| format!("element {}", solids[i]);
    let (mut mesh, kept) = finish_volume(path, &deck.coords, kind, conn, &describe, Some(&deck.node_numbers), &solids)?;
    let mut mesh_index = vec![usize::MAX; deck.coords.len()];
    for (i, &f) in kept.iter().enumerate() {
        mesh_index[f] = i;
    }
    let solid_set: HashSet<u64> = solids.iter().map(|&n| n as u64).collect();
    for (nodes, key) in &deck.set_order {
        let name = if *nodes { &deck.node_sets[key].name } else { &deck.element_sets[key].name };
        let members = deck.resolve(*nodes, key, &mut HashSet::new())?;
        let mut region = Vec::new();
        if *nodes {
            for (k, place) in members {
                region.push(deck.node(k, place, &format!("node set {name}"))?);
            }
        } else {
            let elements: HashSet<u64> = members.iter().map(|(k, _)| *k).collect();
            if solid_set.iter().all(|e| elements.contains(e)) {
                continue;
            }
            for (k, place) in members {
                for &n in &deck.element(k, place, name)?.nodes {
                    region.push(deck.node(n, place, &format!("element {k}"))?);
                }
            }
        }
        let mut region: Vec<usize> = region.into_iter().map(|f| mesh_index[f]).filter(|&i| i != usize::MAX).collect();
        if region.is_empty() {
            continue;
        }
        let same = mesh.regions.keys().find(|r| r.eq_ignore_ascii_case(name)).cloned();
        let entry = mesh.regions.entry(same.unwrap_or_else(|| name.clone())).or_default();
        entry.append(&mut region);
        entry.sort_unstable();
        entry.dedup();
    }
    Ok(mesh)
}
