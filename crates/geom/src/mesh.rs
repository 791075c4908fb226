//! Indexed triangle meshes.

use crate::GeomError;
use std::path::Path;

/// A triangle mesh: positions (metres, frame named by the owner) and CCW-outward triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions, metres.
    pub vertices: Vec<[f32; 3]>,
    /// Vertex indices per triangle, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// A mesh after checking that every index is in range and every coordinate finite.
    pub fn new(vertices: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Result<Self, GeomError> {
        let m = Self {
            vertices,
            triangles,
        };
        m.validate()?;
        Ok(m)
    }

    /// Checks indices and coordinates.
    pub fn validate(&self) -> Result<(), GeomError> {
        if let Some(i) = self
            .vertices
            .iter()
            .position(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(GeomError::InvalidMesh(format!(
                "vertex {i} has a non-finite coordinate"
            )));
        }
        let n = self.vertices.len() as u64;
        if let Some(t) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&i| u64::from(i) >= n))
        {
            return Err(GeomError::InvalidMesh(format!(
                "triangle {t} indexes a vertex beyond the {n} vertices"
            )));
        }
        Ok(())
    }

    /// A lighter copy for display: vertices clustered on a grid of `cell_m` (each cluster at the
    /// mean of its vertices), triangles whose corners fell into fewer than three clusters
    /// dropped. Every vertex moves less than a cell diagonal; the topology may change at that
    /// scale, which a view does not show.
    pub fn clustered(&self, cell_m: f32) -> TriMesh {
        let mut cluster_of = Vec::with_capacity(self.vertices.len());
        let mut index = std::collections::HashMap::new();
        let mut sums: Vec<([f64; 3], u32)> = Vec::new();
        for v in &self.vertices {
            let key = v.map(|x| (x / cell_m).floor() as i64);
            let k = *index.entry(key).or_insert_with(|| {
                sums.push(([0.0; 3], 0));
                (sums.len() - 1) as u32
            });
            let s = &mut sums[k as usize];
            for a in 0..3 {
                s.0[a] += f64::from(v[a]);
            }
            s.1 += 1;
            cluster_of.push(k);
        }
        let vertices = sums
            .iter()
            .map(|(s, n)| s.map(|x| (x / f64::from(*n)) as f32))
            .collect();
        let mut seen = std::collections::HashSet::new();
        let triangles = self
            .triangles
            .iter()
            .map(|t| t.map(|i| cluster_of[i as usize]))
            .filter(|[a, b, c]| a != b && b != c && a != c)
            .filter(|t| {
                // One copy of a triangle that several fine ones collapsed onto.
                let mut key = *t;
                key.sort_unstable();
                seen.insert(key)
            })
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    /// Axis-aligned bounds `(min, max)`, or `None` for an empty mesh.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.vertices.first()?;
        Some(
            self.vertices
                .iter()
                .fold((first, first), |(mut lo, mut hi), v| {
                    for k in 0..3 {
                        lo[k] = lo[k].min(v[k]);
                        hi[k] = hi[k].max(v[k]);
                    }
                    (lo, hi)
                }),
        )
    }

    /// The connected components (triangles sharing vertices) whose |signed volume| is at least
    /// `fraction` of the largest one's, unused vertices dropped: removes the small floating
    /// pieces a learned field can leave far from its data but keeps a real part that meshing
    /// cut off (a mug's handle whose junction is thinner than a cell).
    pub fn main_components(&self, fraction: f64) -> TriMesh {
        let n = self.vertices.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        for t in &self.triangles {
            let a = find(&mut parent, t[0] as usize);
            for &v in &t[1..] {
                let b = find(&mut parent, v as usize);
                parent[b] = a;
            }
        }
        let mut volume = std::collections::HashMap::new();
        for t in &self.triangles {
            *volume
                .entry(find(&mut parent, t[0] as usize))
                .or_insert(0.0) += self.tetra_volume(t);
        }
        let Some(largest) = volume
            .values()
            .map(|v: &f64| v.abs())
            .max_by(f64::total_cmp)
        else {
            return TriMesh::default();
        };
        let mut index = vec![u32::MAX; n];
        let mut out = TriMesh::default();
        for t in &self.triangles {
            if volume[&find(&mut parent, t[0] as usize)].abs() < fraction * largest {
                continue;
            }
            out.triangles.push(t.map(|i| {
                if index[i as usize] == u32::MAX {
                    index[i as usize] = out.vertices.len() as u32;
                    out.vertices.push(self.vertices[i as usize]);
                }
                index[i as usize]
            }));
        }
        out
    }

    /// Signed volume of the tetrahedron (origin, triangle `t`).
    fn tetra_volume(&self, t: &[u32; 3]) -> f64 {
        let [a, b, c] = t.map(|i| self.vertices[i as usize].map(f64::from));
        let cross = [
            b[1] * c[2] - b[2] * c[1],
            b[2] * c[0] - b[0] * c[2],
            b[0] * c[1] - b[1] * c[0],
        ];
        (a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]) / 6.0
    }

    /// Signed volume (m³): positive for a closed mesh with outward CCW triangles.
    pub fn signed_volume(&self) -> f64 {
        self.triangles.iter().map(|t| self.tetra_volume(t)).sum()
    }

    /// Area-weighted vertex normals (unit; zero for isolated vertices).
    pub fn vertex_normals(&self) -> Vec<[f32; 3]> {
        let mut n = vec![[0.0f32; 3]; self.vertices.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let f = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            for &i in t {
                for k in 0..3 {
                    n[i as usize][k] += f[k];
                }
            }
        }
        for v in &mut n {
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if len > 0.0 {
                v.iter_mut().for_each(|x| *x /= len);
            }
        }
        n
    }

    /// Applies `f` to every vertex (e.g. a change of frame).
    pub fn map_vertices(&mut self, f: impl Fn([f32; 3]) -> [f32; 3]) {
        self.vertices.iter_mut().for_each(|v| *v = f(*v));
    }

    /// Writes the mesh in the format its extension names: `.ply` (binary), `.obj`, `.glb`.
    pub fn write(&self, path: &Path) -> Result<(), GeomError> {
        match extension(path).as_deref() {
            Some("ply") => crate::ply::write_ply(self, path),
            Some("obj") => crate::obj::write_obj(self, path),
            Some("glb") => crate::gltf::write_glb(self, path),
            _ => Err(GeomError::format(
                path,
                "unknown mesh extension (use .ply, .obj or .glb)",
            )),
        }
    }

    /// Reads a `.ply` (ASCII or binary) or `.obj` mesh; polygons are fan-triangulated.
    pub fn read(path: &Path) -> Result<Self, GeomError> {
        let mesh = match extension(path).as_deref() {
            Some("ply") => crate::ply::read_ply(path)?,
            Some("obj") => crate::obj::read_obj(path)?,
            _ => {
                return Err(GeomError::format(
                    path,
                    "unknown mesh extension (use .ply or .obj)",
                ));
            }
        };
        mesh.validate()
            .map_err(|e| GeomError::format(path, e.to_string()))?;
        Ok(mesh)
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// A unit cube (for tests and examples), CCW outward.
pub fn unit_cube() -> TriMesh {
    let v = (0..8)
        .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let t = quads
        .iter()
        .flat_map(|q: &[u32; 4]| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    TriMesh {
        vertices: v,
        triangles: t,
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn clustering_keeps_the_shape_with_fewer_vertices() {
        // A finely subdivided unit cube (each face a 20 × 20 grid): 2,402 vertices.
        let n = 20u32;
        let mut m = TriMesh {
            vertices: vec![],
            triangles: vec![],
        };
        for axis in 0..3 {
            for side in [0.0f32, 1.0] {
                let base = m.vertices.len() as u32;
                for i in 0..=n {
                    for j in 0..=n {
                        let mut v = [0.0f32; 3];
                        v[axis] = side;
                        v[(axis + 1) % 3] = i as f32 / n as f32;
                        v[(axis + 2) % 3] = j as f32 / n as f32;
                        m.vertices.push(v);
                    }
                }
                for i in 0..n {
                    for j in 0..n {
                        let a = base + i * (n + 1) + j;
                        m.triangles.push([a, a + 1, a + n + 1]);
                        m.triangles.push([a + 1, a + n + 2, a + n + 1]);
                    }
                }
            }
        }
        let c = m.clustered(0.25);
        assert!(c.validate().is_ok());
        assert!(
            c.vertices.len() < m.vertices.len() / 10,
            "{}",
            c.vertices.len()
        );
        assert!(c.triangles.len() > 50, "{}", c.triangles.len());
        // Every vertex stays within a cell of the cube's surface and inside its bounds.
        for v in &c.vertices {
            assert!(v.iter().all(|x| (-1e-6..=1.0 + 1e-6).contains(x)), "{v:?}");
            let to_surface = v.iter().map(|x| x.min(1.0 - x)).fold(f32::MAX, f32::min);
            assert!(to_surface < 0.25 * 3f32.sqrt(), "{v:?}");
        }
        // No degenerate or duplicate triangles.
        let mut keys: Vec<[u32; 3]> = c
            .triangles
            .iter()
            .map(|t| {
                let mut k = *t;
                k.sort_unstable();
                k
            })
            .collect();
        assert!(keys.iter().all(|[a, b, c]| a != b && b != c));
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), c.triangles.len());
    }
    use super::*;

    #[test]
    fn main_components_drop_the_small_pieces() {
        let big = unit_cube();
        let mut small = unit_cube();
        small.map_vertices(|v| v.map(|x| 0.1 * x + 5.0));
        let mut both = small.clone();
        let off = both.vertices.len() as u32;
        both.vertices.extend(&big.vertices);
        both.triangles
            .extend(big.triangles.iter().map(|t| t.map(|i| i + off)));
        let kept = both.main_components(1.0);
        assert_eq!(
            (kept.vertices.len(), kept.triangles.len()),
            (big.vertices.len(), big.triangles.len())
        );
        assert_eq!(kept.bounds(), big.bounds(), "the unit cube is kept");
        assert!((kept.signed_volume() - 1.0).abs() < 1e-12);
        // A piece of 1 ‰ of the volume goes at 2 %, one of 1.6 % stays at 1 %.
        assert_eq!(
            both.main_components(0.02).triangles.len(),
            big.triangles.len()
        );
        let mut medium = unit_cube();
        medium.map_vertices(|v| v.map(|x| 0.25 * x - 3.0));
        let off = both.vertices.len() as u32;
        both.vertices.extend(&medium.vertices);
        both.triangles
            .extend(medium.triangles.iter().map(|t| t.map(|i| i + off)));
        let kept = both.main_components(0.01);
        assert_eq!(kept.triangles.len(), 2 * big.triangles.len());
        assert!((kept.signed_volume() - (1.0 + 0.25f64.powi(3))).abs() < 1e-6);
        assert_eq!(
            both.main_components(0.02).triangles.len(),
            big.triangles.len()
        );
    }

    #[test]
    fn cube_volume_bounds_and_validation() {
        let c = unit_cube();
        assert!((c.signed_volume() - 1.0).abs() < 1e-12);
        assert_eq!(c.bounds(), Some(([0.0; 3], [1.0; 3])));
        let n = c.vertex_normals();
        // The corner at the origin points into the negative octant.
        assert!(n[0].iter().all(|&x| x < 0.0));
        assert!(TriMesh::new(vec![[0.0; 3]], vec![[0, 0, 1]]).is_err());
        assert!(TriMesh::new(vec![[f32::NAN, 0.0, 0.0]], vec![]).is_err());
    }
}
