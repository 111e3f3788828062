//! Gmsh `.msh`: legacy (`$NOD`/`$ELM`), 2.x ASCII and 4.1 ASCII reading; 2.2 ASCII writing.
//!
//! Physical groups become named regions on reading and regions are written as physical groups:
//! see the [module](super) documentation.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::Path;

use super::text::{Line, LineReader};
use super::{check_for_writing, finish_volume, mesh_cells_flat, read_bytes, write_atomic, Num, VolumeKind};
use crate::{Cells, Mesh, MeshError, Point};

/// The flavour of a Gmsh file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    /// `$NOD` / `$ELM` (Gmsh 1).
    Legacy,
    /// `$MeshFormat` 2.x.
    V2,
    /// `$MeshFormat` 4.1.
    V4,
}

/// Gmsh element type: (dimension, number of nodes, name), or `None` for an unknown type.
fn element_type(ty: u32) -> Option<(u8, usize, &'static str)> {
    Some(match ty {
        1 => (1, 2, "2-node line"),
        2 => (2, 3, "3-node triangle"),
        3 => (2, 4, "4-node quadrangle"),
        4 => (3, 4, "4-node tetrahedron"),
        5 => (3, 8, "8-node hexahedron"),
        6 => (3, 6, "6-node prism"),
        7 => (3, 5, "5-node pyramid"),
        8 => (1, 3, "3-node line"),
        9 => (2, 6, "6-node triangle"),
        10 => (2, 9, "9-node quadrangle"),
        11 => (3, 10, "10-node tetrahedron"),
        12 => (3, 27, "27-node hexahedron"),
        13 => (3, 18, "18-node prism"),
        14 => (3, 14, "14-node pyramid"),
        15 => (0, 1, "1-node point"),
        16 => (2, 8, "8-node quadrangle"),
        17 => (3, 20, "20-node hexahedron"),
        18 => (3, 15, "15-node prism"),
        19 => (3, 13, "13-node pyramid"),
        20 => (2, 9, "9-node incomplete triangle"),
        21 => (2, 10, "10-node triangle"),
        22 => (2, 12, "12-node incomplete triangle"),
        23 => (2, 15, "15-node triangle"),
        24 => (2, 15, "15-node incomplete triangle"),
        25 => (2, 21, "21-node triangle"),
        26 => (1, 4, "4-node line"),
        27 => (1, 5, "5-node line"),
        28 => (1, 6, "6-node line"),
        29 => (3, 20, "20-node tetrahedron"),
        30 => (3, 35, "35-node tetrahedron"),
        31 => (3, 56, "56-node tetrahedron"),
        92 => (3, 64, "64-node hexahedron"),
        93 => (3, 125, "125-node hexahedron"),
        _ => return None,
    })
}

/// Nodes by tag.
#[derive(Default)]
struct Nodes {
    coords: Vec<Point>,
    tags: Vec<usize>,
    index: HashMap<u64, usize>,
}

impl Nodes {
    fn add(&mut self, line: &Line, tag: u64, p: Point) -> Result<(), MeshError> {
        if self.index.insert(tag, self.coords.len()).is_some() {
            return Err(line.error(format!("node tag {tag} appears twice")));
        }
        self.coords.push(p);
        self.tags.push(tag as usize);
        Ok(())
    }
}

/// A physical group: Gmsh identifies it by its dimension and its tag.
type GroupKey = (u8, u64);

/// The elements of one physical group.
#[derive(Default)]
struct Group {
    /// Indices (into the node section) of the nodes of its elements, with repetitions.
    nodes: Vec<usize>,
    /// How many of its elements are volume elements.
    volume_elements: usize,
}

/// The volume elements of a file, with their tags and lines for error messages, and the
/// physical groups of all its elements.
#[derive(Default)]
struct Volume {
    kind: Option<(VolumeKind, usize)>,
    conn: Vec<usize>,
    tags: Vec<u64>,
    lines: Vec<usize>,
    groups: BTreeMap<GroupKey, Group>,
}

/// The index of the node tagged `t`, referred to by element `tag`.
fn node_index(line: &Line, nodes: &Nodes, tag: u64, t: u64) -> Result<usize, MeshError> {
    nodes
        .index
        .get(&t)
        .copied()
        .ok_or_else(|| line.error(format!("element {tag} refers to node {t}, which is not in the node section")))
}

impl Volume {
    /// Reads the node tags left on `line` for element `tag` of type `ty`, which belongs to the
    /// physical groups tagged `physical` (none for 0); keeps linear and quadratic tetrahedra and
    /// hexahedra, and of lower-dimensional elements only their nodes, when they are in a group.
    fn add(&mut self, line: &mut Line, tag: u64, ty: u32, physical: &[u64], nodes: &Nodes) -> Result<(), MeshError> {
        let (dim, n, name) =
            element_type(ty).ok_or_else(|| line.error(format!("element {tag} has unknown element type {ty}")))?;
        if line.remaining() != n {
            return Err(line
                .error(format!("element {tag} ({name}, type {ty}) has {} node tags, expected {n}", line.remaining())));
        }
        if dim < 3 {
            if physical.iter().all(|&p| p == 0) {
                return Ok(());
            }
            let mut element = Vec::with_capacity(n);
            for _ in 0..n {
                let t: u64 = line.parse("node tag")?;
                element.push(node_index(line, nodes, tag, t)?);
            }
            for &p in physical.iter().filter(|&&p| p != 0) {
                self.groups.entry((dim, p)).or_default().nodes.extend_from_slice(&element);
            }
            return Ok(());
        }
        let kind = match ty {
            4 => VolumeKind::Tet,
            5 => VolumeKind::Hex,
            11 => VolumeKind::Tet10,
            _ => {
                return Err(line.error(format!(
                    "element {tag} is a {name} (type {ty}): only 4-node tetrahedra (type 4), \
                     10-node tetrahedra (type 11) and 8-node hexahedra (type 5) are supported"
                )))
            }
        };
        match self.kind {
            None => self.kind = Some((kind, line.no)),
            Some((k, first)) if k != kind => {
                return Err(line.error(format!(
                    "element {tag}: the file mixes {} (first at line {first}) and {}; a mesh holds one kind of cell",
                    k.plural(),
                    kind.plural()
                )))
            }
            Some(_) => {}
        }
        let start = self.conn.len();
        for _ in 0..n {
            let t: u64 = line.parse("node tag")?;
            self.conn.push(node_index(line, nodes, tag, t)?);
        }
        for &p in physical.iter().filter(|&&p| p != 0) {
            let group = self.groups.entry((dim, p)).or_default();
            group.nodes.extend_from_slice(&self.conn[start..]);
            group.volume_elements += 1;
        }
        if kind == VolumeKind::Tet10 {
            // Gmsh numbers the mid-edge nodes of 3-2 and 3-1 the other way round from VTK.
            self.conn.swap(start + 8, start + 9);
        }
        self.tags.push(tag);
        self.lines.push(line.no);
        Ok(())
    }
}

/// Reads a Gmsh mesh (legacy `$NOD`/`$ELM`, 2.x ASCII or 4.1 ASCII) and keeps its linear
/// tetrahedra or hexahedra; its physical groups become regions (see the [module](super)
/// documentation for what is kept and how groups are named).
pub fn read_gmsh(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    let path = path.as_ref();
    let bytes = read_bytes(path)?;
    let text = String::from_utf8_lossy(&bytes);
    let mut lines = LineReader::new(path, &text);
    let first = lines.next_line().ok_or_else(|| MeshError::parse(path, "empty file"))?;
    let (format, mut pending) = match first.text.trim() {
        "$NOD" => (Format::Legacy, Some(first)),
        "$MeshFormat" => (read_mesh_format(&mut lines)?, None),
        other => {
            return Err(first.error(format!(
                "not a Gmsh mesh: expected $MeshFormat or $NOD, found '{}'",
                other.chars().take(40).collect::<String>()
            )))
        }
    };
    let mut nodes: Option<Nodes> = None;
    let mut volume: Option<Volume> = None;
    let mut names: HashMap<GroupKey, String> = HashMap::new();
    let mut entities: HashMap<(u32, i64), Vec<u64>> = HashMap::new();
    while let Some(line) = pending.take().or_else(|| lines.next_line()) {
        let name = line.text.trim();
        if !name.starts_with('$') {
            return Err(line.error(format!("expected a section header such as $Nodes or $Elements, found '{name}'")));
        }
        let is_nodes = matches!((format, name), (Format::Legacy, "$NOD") | (Format::V2 | Format::V4, "$Nodes"));
        let is_elements = matches!((format, name), (Format::Legacy, "$ELM") | (Format::V2 | Format::V4, "$Elements"));
        if is_nodes {
            if nodes.is_some() {
                return Err(line.error("a second node section"));
            }
            nodes = Some(match format {
                Format::V4 => read_nodes_v4(&mut lines, &line)?,
                _ => read_nodes_v2(&mut lines, &line)?,
            });
        } else if is_elements {
            let nodes = nodes.as_ref().ok_or_else(|| line.error("element section before the node section"))?;
            if volume.is_some() {
                return Err(line.error("a second element section"));
            }
            volume = Some(match format {
                Format::V4 => read_elements_v4(&mut lines, &line, nodes, &entities)?,
                _ => read_elements_v2(&mut lines, &line, format, nodes)?,
            });
        } else if name == "$PhysicalNames" {
            read_physical_names(&mut lines, &line, &mut names)?;
        } else if format == Format::V4 && name == "$Entities" {
            entities = read_entities_v4(&mut lines, &line)?;
        } else {
            skip_section(&mut lines, &line)?;
        }
    }
    let nodes = nodes.ok_or_else(|| MeshError::parse(path, "no node section ($Nodes or $NOD)"))?;
    let volume = volume.ok_or_else(|| MeshError::parse(path, "no element section ($Elements or $ELM)"))?;
    let Some((kind, _)) = volume.kind else {
        return Err(MeshError::parse(path, "no tetrahedra (type 4) or hexahedra (type 5): not a volume mesh"));
    };
    let describe = |i: usize| format!("element {} (line {})", volume.tags[i], volume.lines[i]);
    let tags: Vec<usize> = volume.tags.iter().map(|&t| t as usize).collect();
    let (mut mesh, kept) =
        finish_volume(path, &nodes.coords, kind, volume.conn.clone(), &describe, Some(&nodes.tags), &tags)?;
    mesh.regions = physical_regions(&volume, &names, &kept, nodes.coords.len());
    Ok(mesh)
}

/// The regions of the physical groups of a file: one per group name (`physical_<tag>` for a group
/// without one), holding the mesh nodes of the group's elements. A volume group that holds every
/// volume element is the whole mesh, not a region. A name that `$PhysicalNames` gives a volume
/// group and groups of lower dimension (a part and its boundary, or the whole mesh and its
/// surface) would mean either: each then takes its dimension's suffix (`liver_volume`,
/// `liver_surface`), the whole mesh's group too. `kept` maps mesh nodes to file nodes.
fn physical_regions(
    volume: &Volume,
    names: &HashMap<GroupKey, String>,
    kept: &[usize],
    file_nodes: usize,
) -> BTreeMap<String, Vec<usize>> {
    let mut mesh_index = vec![usize::MAX; file_nodes];
    for (i, &f) in kept.iter().enumerate() {
        mesh_index[f] = i;
    }
    let name = |key: &GroupKey| names.get(key).cloned().unwrap_or_else(|| format!("physical_{}", key.1));
    // Named volume groups only: an unnamed one's `physical_<tag>` is no name a user gave.
    let volume_names: Vec<&String> = volume.groups.keys().filter(|k| k.0 == 3).filter_map(|k| names.get(k)).collect();
    let shared = |n: &String| volume_names.contains(&n) && volume.groups.keys().any(|k| k.0 < 3 && name(k) == *n);
    let mut regions: BTreeMap<String, Vec<usize>> = BTreeMap::new();
    for (key, group) in &volume.groups {
        let plain = name(key);
        let split = shared(&plain);
        if group.volume_elements == volume.tags.len() && !split {
            continue;
        }
        let set: Vec<usize> = group.nodes.iter().map(|&f| mesh_index[f]).filter(|&i| i != usize::MAX).collect();
        if set.is_empty() {
            continue;
        }
        let name = match split {
            true => format!("{plain}_{}", ["point", "curve", "surface", "volume"][key.0 as usize]),
            false => plain,
        };
        regions.entry(name).or_default().extend(set);
    }
    for set in regions.values_mut() {
        set.sort_unstable();
        set.dedup();
    }
    regions
}

/// `$PhysicalNames`: a count, then `dimension tag "name"` lines. A name is read between its
/// first two double quotes (as Gmsh reads it), or is the rest of the line when unquoted.
fn read_physical_names(
    lines: &mut LineReader,
    header: &Line,
    names: &mut HashMap<GroupKey, String>,
) -> Result<(), MeshError> {
    let n = read_count(lines, "number of physical names")?;
    for _ in 0..n {
        let mut line = lines.expect(&format!("the {n} physical names declared at line {}", header.no + 1))?;
        let dim: u8 = line.parse("physical group dimension")?;
        let tag: u64 = line.parse("physical group tag")?;
        if dim > 3 {
            return Err(line.error(format!("physical group dimension {dim} is not 0, 1, 2 or 3")));
        }
        let rest = line.text.trim_start();
        let rest = rest.split_once(char::is_whitespace).map_or("", |(_, r)| r).trim_start();
        let rest = rest.split_once(char::is_whitespace).map_or("", |(_, r)| r).trim();
        let name = match rest.strip_prefix('"') {
            Some(quoted) => quoted.split('"').next().unwrap_or(""),
            None => rest,
        };
        if !name.is_empty() {
            names.insert((dim, tag), name.to_string());
        }
    }
    expect_end(lines, "$EndPhysicalNames", &format!("after the {n} physical names declared at line {}", header.no + 1))
}

/// `$Entities` (4.1): the physical tags of each entity, by (dimension, entity tag). Each entity
/// is one line: its tag, its coordinates (3 for a point, a bounding box of 6 otherwise), its
/// physical tags, then its bounding entities (not needed).
fn read_entities_v4(lines: &mut LineReader, header: &Line) -> Result<HashMap<(u32, i64), Vec<u64>>, MeshError> {
    let mut line = lines.expect("the $Entities header")?;
    let mut counts = [0usize; 4];
    for (dim, count) in counts.iter_mut().enumerate() {
        *count =
            line.parse(["number of points", "number of curves", "number of surfaces", "number of volumes"][dim])?;
    }
    line.finish("the $Entities header")?;
    let mut entities = HashMap::new();
    for (dim, &count) in counts.iter().enumerate() {
        for _ in 0..count {
            let mut line = lines.expect(&format!("the entities declared at line {}", header.no + 1))?;
            let tag: i64 = line.parse("entity tag")?;
            for _ in 0..if dim == 0 { 3 } else { 6 } {
                let _: f64 = line.parse("entity coordinate")?;
            }
            let n: usize = line.parse("number of physical tags")?;
            let mut physical = Vec::with_capacity(n.min(line.remaining()));
            for _ in 0..n {
                let p: i64 = line.parse("physical tag")?;
                physical.push(p.unsigned_abs());
            }
            if !physical.is_empty() {
                entities.insert((dim as u32, tag), physical);
            }
        }
    }
    expect_end(lines, "$EndEntities", &format!("after the entities declared at line {}", header.no + 1))?;
    Ok(entities)
}

/// Parses the body of `$MeshFormat` (after its header line) up to `$EndMeshFormat`.
fn read_mesh_format(lines: &mut LineReader) -> Result<Format, MeshError> {
    let mut line = lines.expect("$MeshFormat")?;
    let version = line.token("format version")?;
    let file_type: u32 = line.parse("file type (0 for ASCII, 1 for binary)")?;
    let format = if version.starts_with("2.") {
        Format::V2
    } else if version == "4.1" {
        Format::V4
    } else {
        return Err(line.error(format!(
            "Gmsh format version {version} is not supported (legacy, 2.x and 4.1 are); \
             re-export with gmsh -format msh22 or msh41"
        )));
    };
    if file_type != 0 {
        return Err(line.error("binary Gmsh files are not supported: re-export as ASCII (gmsh without -bin)"));
    }
    // A binary file would hold an endianness marker here; ASCII files go straight to the end.
    expect_end(lines, "$EndMeshFormat", "after the format line")?;
    Ok(format)
}

/// Reads the next line and checks that it is the section end `end` (case-insensitive).
fn expect_end(lines: &mut LineReader, end: &str, context: &str) -> Result<(), MeshError> {
    let line = lines.expect(end)?;
    if line.text.trim().eq_ignore_ascii_case(end) {
        Ok(())
    } else {
        Err(line.error(format!("expected {end} {context}, found '{}'", line.text.trim())))
    }
}

/// Skips a section that is not needed, up to its `$End...` line.
fn skip_section(lines: &mut LineReader, header: &Line) -> Result<(), MeshError> {
    let name = header.text.trim();
    let end = format!("$End{}", &name[1..]);
    while let Some(line) = lines.next_line() {
        if line.text.trim().eq_ignore_ascii_case(&end) {
            return Ok(());
        }
    }
    Err(header.error(format!("section {name} is not closed by {end} (truncated file?)")))
}

/// A count on its own line.
fn read_count(lines: &mut LineReader, what: &str) -> Result<usize, MeshError> {
    let mut line = lines.expect(what)?;
    let n = line.parse(what)?;
    line.finish(what)?;
    Ok(n)
}

/// `$NOD` (legacy) or `$Nodes` (2.x): a count, then `tag x y z` lines.
fn read_nodes_v2(lines: &mut LineReader, header: &Line) -> Result<Nodes, MeshError> {
    let end = if header.text.trim() == "$NOD" { "$ENDNOD" } else { "$EndNodes" };
    let n = read_count(lines, "number of nodes")?;
    let mut nodes = Nodes::default();
    for _ in 0..n {
        let mut line = lines.expect(&format!("the {n} nodes declared at line {}", header.no + 1))?;
        if line.text.trim_start().starts_with('$') {
            return Err(line.error(format!(
                "found '{}' after {} of the {n} nodes declared at line {}",
                line.text.trim(),
                nodes.coords.len(),
                header.no + 1
            )));
        }
        let tag = line.parse("node tag")?;
        let p = line.point("node coordinate")?;
        line.finish("the node coordinates")?;
        nodes.add(&line, tag, p)?;
    }
    expect_end(lines, end, &format!("after the {n} nodes declared at line {}", header.no + 1))?;
    Ok(nodes)
}

/// `$ELM` (legacy) or `$Elements` (2.x): a count, then one element per line.
fn read_elements_v2(lines: &mut LineReader, header: &Line, format: Format, nodes: &Nodes) -> Result<Volume, MeshError> {
    let end = if format == Format::Legacy { "$ENDELM" } else { "$EndElements" };
    let n = read_count(lines, "number of elements")?;
    let mut volume = Volume::default();
    for read in 0..n {
        let mut line = lines.expect(&format!("the {n} elements declared at line {}", header.no + 1))?;
        if line.text.trim_start().starts_with('$') {
            return Err(line.error(format!(
                "found '{}' after {read} of the {n} elements declared at line {}",
                line.text.trim(),
                header.no + 1
            )));
        }
        let tag: u64 = line.parse("element tag")?;
        let ty: u32 = line.parse("element type")?;
        // The physical group comes first: 0 (or no tag at all) for none.
        let mut physical = 0i64;
        if format == Format::Legacy {
            physical = line.parse("physical region")?;
            let _elementary: i64 = line.parse("elementary region")?;
            let count: usize = line.parse("number of nodes")?;
            if count != line.remaining() {
                return Err(line.error(format!("element {tag} declares {count} nodes but lists {}", line.remaining())));
            }
        } else {
            let tags: usize = line.parse("number of tags")?;
            for k in 0..tags {
                let value: i64 = line.parse("element tag value")?;
                if k == 0 {
                    physical = value;
                }
            }
        }
        volume.add(&mut line, tag, ty, &[physical.max(0) as u64], nodes)?;
    }
    expect_end(lines, end, &format!("after the {n} elements declared at line {}", header.no + 1))?;
    Ok(volume)
}

/// `$Nodes` (4.1): a header, then entity blocks of node tags followed by their coordinates.
fn read_nodes_v4(lines: &mut LineReader, header: &Line) -> Result<Nodes, MeshError> {
    let mut line = lines.expect("the $Nodes header")?;
    let blocks: usize = line.parse("number of entity blocks")?;
    let total: usize = line.parse("number of nodes")?;
    let _min: u64 = line.parse("minimum node tag")?;
    let _max: u64 = line.parse("maximum node tag")?;
    line.finish("the $Nodes header")?;
    let count_line = line.no;
    let mut nodes = Nodes::default();
    for _ in 0..blocks {
        let mut line = lines.expect("a node entity block")?;
        let _dim: u32 = line.parse("entity dimension")?;
        let _entity: i64 = line.parse("entity tag")?;
        let parametric: u32 = line.parse("parametric flag")?;
        let n: usize = line.parse("number of nodes in block")?;
        line.finish("the node block header")?;
        let mut tags = Vec::new();
        for _ in 0..n {
            let mut line = lines.expect("node tags")?;
            tags.push((line.parse::<u64>("node tag")?, line.no));
            line.finish("the node tag")?;
        }
        for &(tag, _) in &tags {
            let mut line = lines.expect("node coordinates")?;
            let p = line.point("node coordinate")?;
            if parametric == 0 {
                line.finish("the node coordinates")?;
            }
            nodes.add(&line, tag, p)?;
        }
    }
    if nodes.coords.len() != total {
        return Err(header.error(format!(
            "the header at line {count_line} declares {total} nodes, but the blocks hold {}",
            nodes.coords.len()
        )));
    }
    expect_end(lines, "$EndNodes", &format!("after the {blocks} node blocks declared at line {count_line}"))?;
    Ok(nodes)
}

/// `$Elements` (4.1): a header, then entity blocks of elements of one type, in the physical groups
/// of their entity.
fn read_elements_v4(
    lines: &mut LineReader,
    header: &Line,
    nodes: &Nodes,
    entities: &HashMap<(u32, i64), Vec<u64>>,
) -> Result<Volume, MeshError> {
    let mut line = lines.expect("the $Elements header")?;
    let blocks: usize = line.parse("number of entity blocks")?;
    let total: usize = line.parse("number of elements")?;
    let _min: u64 = line.parse("minimum element tag")?;
    let _max: u64 = line.parse("maximum element tag")?;
    line.finish("the $Elements header")?;
    let count_line = line.no;
    let mut volume = Volume::default();
    let mut read = 0;
    for _ in 0..blocks {
        let mut line = lines.expect("an element entity block")?;
        let dim: u32 = line.parse("entity dimension")?;
        let entity: i64 = line.parse("entity tag")?;
        let ty: u32 = line.parse("element type")?;
        let n: usize = line.parse("number of elements in block")?;
        line.finish("the element block header")?;
        let physical = entities.get(&(dim, entity)).map_or(&[][..], Vec::as_slice);
        for _ in 0..n {
            let mut line = lines.expect("elements")?;
            let tag: u64 = line.parse("element tag")?;
            volume.add(&mut line, tag, ty, physical, nodes)?;
        }
        read += n;
    }
    if read != total {
        return Err(header
            .error(format!("the header at line {count_line} declares {total} elements, but the blocks hold {read}")));
    }
    expect_end(lines, "$EndElements", &format!("after the {blocks} element blocks declared at line {count_line}"))?;
    Ok(volume)
}

/// Writes a volume mesh as Gmsh 2.2 ASCII (node and element tags from 1, the cells in physical
/// and elementary group 1). Coordinates are written exactly. Each non-empty region becomes a
/// named 0-dimensional physical group (tags 1, 2, ... in name order) of point elements (type 15),
/// one per region node, after the cells: `elm-number 15 2 physical elementary node`, the
/// elementary tag being the group's. A region name must be non-empty, without double quotes or
/// control characters, as `$PhysicalNames` holds it in quotes on one line.
pub fn write_msh(path: impl AsRef<Path>, mesh: &Mesh) -> Result<(), MeshError> {
    let path = path.as_ref();
    let (_, k, mut conn) = mesh_cells_flat(mesh);
    check_for_writing(mesh.num_nodes(), mesh.cells.len(), &conn, &[])?;
    let regions: Vec<(&String, &Vec<usize>)> = mesh.regions.iter().filter(|(_, set)| !set.is_empty()).collect();
    for (name, set) in &regions {
        if name.is_empty() || name.chars().any(|c| c == '"' || c.is_control()) {
            return Err(MeshError::Invalid(format!(
                "region name {name:?} cannot be a Gmsh physical name (empty, or holds a double quote or a control \
                 character)"
            )));
        }
        if let Some(&bad) = set.iter().find(|&&i| i >= mesh.num_nodes()) {
            return Err(MeshError::Invalid(format!(
                "region '{name}' refers to node {bad}, but there are {} nodes",
                mesh.num_nodes()
            )));
        }
    }
    let ty = match mesh.cells {
        Cells::Tet4(_) => 4,
        Cells::Hex8(_) => 5,
        Cells::Tet10(_) => {
            conn.chunks_exact_mut(10).for_each(|c| c.swap(8, 9));
            11
        }
    };
    let points: usize = regions.iter().map(|(_, set)| set.len()).sum();
    write_atomic(path, |w| {
        writeln!(w, "$MeshFormat\n2.2 0 8\n$EndMeshFormat")?;
        if !regions.is_empty() {
            writeln!(w, "$PhysicalNames\n{}", regions.len())?;
            for (g, (name, _)) in regions.iter().enumerate() {
                writeln!(w, "0 {} \"{name}\"", g + 1)?;
            }
            writeln!(w, "$EndPhysicalNames")?;
        }
        writeln!(w, "$Nodes\n{}", mesh.num_nodes())?;
        for (i, p) in mesh.nodes.iter().enumerate() {
            writeln!(w, "{} {} {} {}", i + 1, Num(p[0]), Num(p[1]), Num(p[2]))?;
        }
        writeln!(w, "$EndNodes\n$Elements\n{}", mesh.cells.len() + points)?;
        for (e, cell) in conn.chunks_exact(k).enumerate() {
            write!(w, "{} {ty} 2 1 1", e + 1)?;
            for &i in cell {
                write!(w, " {}", i + 1)?;
            }
            writeln!(w)?;
        }
        let mut e = mesh.cells.len();
        for (g, (_, set)) in regions.iter().enumerate() {
            for &i in set.iter() {
                e += 1;
                writeln!(w, "{e} 15 2 {0} {0} {1}", g + 1, i + 1)?;
            }
        }
        writeln!(w, "$EndElements")
    })
    .map_err(MeshError::from)
}
