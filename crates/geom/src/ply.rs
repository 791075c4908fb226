//! PLY: binary little-endian writing; ASCII and binary little-endian reading of `vertex`
//! (x, y, z as float/double, other properties skipped) and `face` (a list of indices).

use crate::{GeomError, TriMesh};
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::Path;

/// Writes a binary little-endian PLY (float x, y, z; uchar-count uint indices).
pub fn write_ply(mesh: &TriMesh, path: &Path) -> Result<(), GeomError> {
    let io = |e| GeomError::io(path, e);
    let mut w = BufWriter::new(std::fs::File::create(path).map_err(io)?);
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment irmirror, metres\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nelement face {}\n\
         property list uchar uint vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    w.write_all(header.as_bytes()).map_err(io)?;
    for v in &mesh.vertices {
        for x in v {
            w.write_all(&x.to_le_bytes()).map_err(io)?;
        }
    }
    for t in &mesh.triangles {
        w.write_all(&[3u8]).map_err(io)?;
        for i in t {
            w.write_all(&i.to_le_bytes()).map_err(io)?;
        }
    }
    w.flush().map_err(io)
}

#[derive(Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }
    fn read_bin(self, r: &mut impl Read) -> std::io::Result<f64> {
        macro_rules! rd {
            ($t:ty) => {{
                let mut b = [0u8; std::mem::size_of::<$t>()];
                r.read_exact(&mut b)?;
                <$t>::from_le_bytes(b) as f64
            }};
        }
        Ok(match self {
            Self::I8 => rd!(i8),
            Self::U8 => rd!(u8),
            Self::I16 => rd!(i16),
            Self::U16 => rd!(u16),
            Self::I32 => rd!(i32),
            Self::U32 => rd!(u32),
            Self::F32 => rd!(f32),
            Self::F64 => rd!(f64),
        })
    }
}

enum Prop {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

/// Reads an ASCII or binary little-endian PLY file.
pub fn read_ply(path: &Path) -> Result<TriMesh, GeomError> {
    let fail = |r: String| GeomError::format(path, r);
    let file = std::fs::File::open(path).map_err(|e| GeomError::io(path, e))?;
    let mut r = BufReader::new(file);
    let mut line = String::new();
    let mut next_line = |r: &mut BufReader<std::fs::File>| -> Result<String, GeomError> {
        line.clear();
        let n = r.read_line(&mut line).map_err(|e| GeomError::io(path, e))?;
        if n == 0 {
            return Err(GeomError::format(path, "file ends inside the PLY header"));
        }
        Ok(line.trim().to_string())
    };
    if next_line(&mut r)? != "ply" {
        return Err(fail("not a PLY file (no 'ply' magic)".into()));
    }
    let mut binary = false;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let l = next_line(&mut r)?;
        let tok: Vec<&str> = l.split_whitespace().collect();
        match tok.as_slice() {
            ["format", "ascii", _] => binary = false,
            ["format", "binary_little_endian", _] => binary = true,
            ["format", f, ..] => return Err(fail(format!("unsupported PLY format '{f}'"))),
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| fail(format!("bad element count '{count}'")))?,
                props: vec![],
            }),
            ["property", "list", c, i, name] => {
                let (c, i) = (Scalar::parse(c), Scalar::parse(i));
                let el = elements
                    .last_mut()
                    .ok_or_else(|| fail("property before element".into()))?;
                match (c, i) {
                    (Some(c), Some(i)) => el.props.push(Prop::List(name.to_string(), c, i)),
                    _ => return Err(fail(format!("unknown list types in '{l}'"))),
                }
            }
            ["property", t, name] => {
                let t = Scalar::parse(t)
                    .ok_or_else(|| fail(format!("unknown property type in '{l}'")))?;
                let el = elements
                    .last_mut()
                    .ok_or_else(|| fail("property before element".into()))?;
                el.props.push(Prop::Scalar(name.to_string(), t));
            }
            ["end_header"] => break,
            _ => {} // comments, obj_info
        }
    }
    let mut mesh = TriMesh::default();
    let mut ascii_tokens: Vec<String> = Vec::new();
    if !binary {
        let mut rest = String::new();
        r.read_to_string(&mut rest)
            .map_err(|e| GeomError::io(path, e))?;
        ascii_tokens = rest.split_whitespace().rev().map(str::to_string).collect();
    }
    let truncated = || fail("file is truncated (fewer elements than the header declares)".into());
    let mut read_val = |r: &mut BufReader<std::fs::File>, t: Scalar| -> Result<f64, GeomError> {
        if binary {
            t.read_bin(r).map_err(|_| truncated())
        } else {
            let s = ascii_tokens.pop().ok_or_else(truncated)?;
            s.parse::<f64>()
                .map_err(|_| fail(format!("'{s}' is not a number")))
        }
    };
    for el in &elements {
        if el.count > 100_000_000 {
            return Err(fail(format!(
                "element '{}' declares an implausible count {}",
                el.name, el.count
            )));
        }
        for _ in 0..el.count {
            let mut xyz = [0.0f32; 3];
            for p in &el.props {
                match p {
                    Prop::Scalar(name, t) => {
                        let v = read_val(&mut r, *t)?;
                        match name.as_str() {
                            "x" => xyz[0] = v as f32,
                            "y" => xyz[1] = v as f32,
                            "z" => xyz[2] = v as f32,
                            _ => {}
                        }
                    }
                    Prop::List(name, c, i) => {
                        let n = read_val(&mut r, *c)? as usize;
                        let mut idx = Vec::with_capacity(n);
                        for _ in 0..n {
                            let v = read_val(&mut r, *i)?;
                            if v < 0.0 {
                                return Err(fail(format!("negative vertex index {v}")));
                            }
                            idx.push(v as u32);
                        }
                        if el.name == "face" && (name == "vertex_indices" || name == "vertex_index")
                        {
                            for k in 1..n.saturating_sub(1) {
                                mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
                            }
                        }
                    }
                }
            }
            if el.name == "vertex" {
                mesh.vertices.push(xyz);
            }
        }
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::unit_cube;

    #[test]
    fn binary_round_trip_and_ascii_read() {
        let dir = std::env::temp_dir().join(format!("irmirror-ply-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cube = unit_cube();
        let p = dir.join("cube.ply");
        cube.write(&p).unwrap();
        assert_eq!(TriMesh::read(&p).unwrap(), cube);

        let a = dir.join("quad.ply");
        std::fs::write(&a, "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n4 0 1 2 3\n").unwrap();
        let q = TriMesh::read(&a).unwrap();
        assert_eq!(q.vertices.len(), 4);
        assert_eq!(q.triangles, vec![[0, 1, 2], [0, 2, 3]]);

        // Truncation and bad indices are errors, not panics.
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 7]).unwrap();
        assert!(
            TriMesh::read(&p)
                .unwrap_err()
                .to_string()
                .contains("truncated")
        );
        std::fs::write(&a, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 2\n").unwrap();
        assert!(TriMesh::read(&a).is_err());
        std::fs::write(&a, "not a ply").unwrap();
        assert!(TriMesh::read(&a).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
