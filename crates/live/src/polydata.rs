//! The POLYDATA message of the OpenIGTLink standard (version 2 of the protocol onwards), as 3D
//! Slicer's OpenIGTLinkIF, PLUS and pyigtl read and write it: a header of ten unsigned 32-bit
//! counts (points; vertices, lines, polygons and triangle strips, each as a number of cells and a
//! size in bytes; attributes), the points as big-endian 32-bit floats, then each cell list as
//! `n, i1 … in` in unsigned 32-bit integers, then the attributes.

use crate::igtl::Content;

/// Bytes of the header: ten unsigned 32-bit counts.
const HEADER: usize = 40;

/// A POLYDATA message: points and triangles (other cells and attributes are read past).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolyData {
    /// The points (the stream's unit).
    pub points: Vec<[f32; 3]>,
    /// Triangles, as indices into `points` (sent as polygons of three points).
    pub triangles: Vec<[u32; 3]>,
}

impl Content for PolyData {
    const TYPE: &'static str = "POLYDATA";

    fn encode(&self) -> Result<Vec<u8>, String> {
        let too_many = |what: &str| format!("too many {what} for 32-bit counts");
        let n = u32::try_from(self.points.len()).map_err(|_| too_many("points"))?;
        let polygons = u32::try_from(self.triangles.len()).map_err(|_| too_many("triangles"))?;
        let polygon_bytes = polygons.checked_mul(16).ok_or_else(|| too_many("triangles"))?;
        let mut out = Vec::with_capacity(HEADER + 12 * self.points.len() + 16 * self.triangles.len());
        for count in [n, 0, 0, 0, 0, polygons, polygon_bytes, 0, 0, 0] {
            out.extend_from_slice(&count.to_be_bytes());
        }
        for p in &self.points {
            p.iter().for_each(|x| out.extend_from_slice(&x.to_be_bytes()));
        }
        for t in &self.triangles {
            [3, t[0], t[1], t[2]].iter().for_each(|i| out.extend_from_slice(&i.to_be_bytes()));
        }
        Ok(out)
    }

    fn decode(data: &[u8]) -> Result<PolyData, String> {
        if data.len() < HEADER {
            return Err(format!("{} bytes, shorter than its {HEADER}-byte header", data.len()));
        }
        let word = |at: usize| u32::from_be_bytes([data[at], data[at + 1], data[at + 2], data[at + 3]]);
        let counts: Vec<u64> = (0..10).map(|k| u64::from(word(4 * k))).collect();
        let points_end = HEADER as u64 + 12 * counts[0];
        // Vertices, lines, polygons and strips: their sizes in bytes follow their counts.
        let cells: u64 = [2, 4, 6, 8].iter().map(|&k| counts[k]).sum();
        if points_end + cells > data.len() as u64 {
            return Err(format!(
                "the header announces {} points and {cells} bytes of cells, more than the {} bytes sent",
                counts[0],
                data.len()
            ));
        }
        let points = data[HEADER..points_end as usize]
            .chunks_exact(12)
            .map(|c| std::array::from_fn(|d| f32::from_be_bytes([c[4 * d], c[4 * d + 1], c[4 * d + 2], c[4 * d + 3]])))
            .collect();
        let polygons_at = (points_end + counts[2] + counts[4]) as usize;
        let triangles = read_triangles(&data[polygons_at..polygons_at + counts[6] as usize], counts[5], counts[0])?;
        Ok(PolyData { points, triangles })
    }
}

/// The triangles of a polygon list of `n` cells over `points` points (other polygons are left
/// out); an error when the list does not hold `n` cells or an index is out of range.
fn read_triangles(list: &[u8], n: u64, points: u64) -> Result<Vec<[u32; 3]>, String> {
    let words: Vec<u32> =
        list.chunks_exact(4).map(|c| u32::from_be_bytes([c[0], c[1], c[2], c[3]])).collect::<Vec<_>>();
    let mut triangles = Vec::new();
    let (mut at, mut cells) = (0usize, 0u64);
    while at < words.len() {
        let size = words[at] as usize;
        let cell = words.get(at + 1..at + 1 + size).ok_or("a polygon runs past its list")?;
        if cell.iter().any(|&i| u64::from(i) >= points) {
            return Err("a polygon's point index is out of range".into());
        }
        if let [a, b, c] = *cell {
            triangles.push([a, b, c]);
        }
        at += 1 + size;
        cells += 1;
    }
    if cells != n || !list.len().is_multiple_of(4) {
        return Err(format!("{cells} polygons in a list announced to hold {n}"));
    }
    Ok(triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A message as the OpenIGTLink library lays it out, written by hand: 2 points, 1 vertex cell
    /// and 1 triangle.
    fn by_hand() -> Vec<u8> {
        let mut b = Vec::new();
        for c in [3u32, 1, 8, 0, 0, 1, 16, 0, 0, 0] {
            b.extend_from_slice(&c.to_be_bytes());
        }
        for x in [0.0f32, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.5] {
            b.extend_from_slice(&x.to_be_bytes());
        }
        for i in [1u32, 0, 3, 0, 1, 2] {
            b.extend_from_slice(&i.to_be_bytes());
        }
        b
    }

    #[test]
    fn the_standard_layout_is_read_and_written() {
        let message = PolyData::decode(&by_hand()).unwrap();
        assert_eq!(message.points, [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.5]]);
        assert_eq!(message.triangles, [[0, 1, 2]]);
        let written = message.encode().unwrap();
        // Written back without the vertex cell: the counts say so, the rest is the same bytes.
        let mut expected = by_hand();
        expected.drain(76..84);
        expected[4..12].copy_from_slice(&[0; 8]);
        assert_eq!(written, expected);
        assert_eq!(PolyData::decode(&written).unwrap(), message);
    }

    #[test]
    fn malformed_messages_are_errors() {
        let e = |b: &[u8]| PolyData::decode(b).unwrap_err();
        let good = by_hand();
        assert!(e(&good[..30]).contains("shorter than"));
        assert!(e(&good[..good.len() - 4]).contains("more than the"));
        let mut lying = good.clone();
        lying[0..4].copy_from_slice(&1000u32.to_be_bytes());
        assert!(e(&lying).contains("1000 points"));
        let mut out_of_range = good.clone();
        let last = out_of_range.len() - 4;
        out_of_range[last..].copy_from_slice(&9u32.to_be_bytes());
        assert!(e(&out_of_range).contains("out of range"));
        let mut runs_past = good;
        let at = runs_past.len() - 16;
        runs_past[at..at + 4].copy_from_slice(&7u32.to_be_bytes());
        assert!(e(&runs_past).contains("runs past"));
    }
}
