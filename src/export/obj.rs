//! Wavefront OBJ + MTL + PNG of the plane mesh, as the reference writes for Blender
//! (`planes_mesh.obj`, `planes_mesh.mtl`, `planes_mesh.png`; spec §10.3).
//!
//! One `v` and one `vt` per corner (1-based, vertex `j` uses texture coordinate `j`), two `f` per
//! quad. The material `planes` maps the RGBA atlas as diffuse colour (`map_Kd`) and as dissolve
//! (`map_d`, the alpha channel), which Blender's OBJ importer wires to the alpha input.

use super::ExportError;
use super::atlas::encode_png;
use super::planes::{PlaneMesh, QUAD_TRIANGLES};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The OBJ text of `mesh`, using the material library `mtl_name`.
pub fn obj_text(mesh: &PlaneMesh, mtl_name: &str) -> String {
    let mut s = String::with_capacity(mesh.corners.len() * 4 * 60);
    let _ = writeln!(s, "# bbsplat planes export: {} billboards", mesh.corners.len());
    let _ = writeln!(s, "mtllib {mtl_name}");
    for quad in &mesh.corners {
        for p in quad {
            let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
        }
    }
    for quad in &mesh.uvs {
        for t in quad {
            let _ = writeln!(s, "vt {} {}", t.x, t.y);
        }
    }
    let _ = writeln!(s, "usemtl planes");
    for k in 0..mesh.corners.len() {
        let base = 4 * k as u32 + 1;
        for tri in QUAD_TRIANGLES {
            let [a, b, c] = tri.map(|j| base + j);
            let _ = writeln!(s, "f {a}/{a} {b}/{b} {c}/{c}");
        }
    }
    s
}

/// The MTL text of the material `planes` textured by `png_name`.
pub fn mtl_text(png_name: &str) -> String {
    format!(
        "# bbsplat planes export\nnewmtl planes\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nd 1\nmap_Kd {png_name}\nmap_d {png_name}\n"
    )
}

/// Writes `<dir>/<stem>.obj`, `.mtl` and `.png`; returns the files written with their sizes.
pub fn write_obj(dir: &Path, stem: &str, mesh: &PlaneMesh) -> Result<Vec<(PathBuf, u64)>, ExportError> {
    let png = encode_png(&mesh.atlas)?;
    let (obj_name, mtl_name, png_name) = (format!("{stem}.obj"), format!("{stem}.mtl"), format!("{stem}.png"));
    let files = [
        (dir.join(&obj_name), obj_text(mesh, &mtl_name).into_bytes()),
        (dir.join(&mtl_name), mtl_text(&png_name).into_bytes()),
        (dir.join(&png_name), png),
    ];
    let mut written = Vec::new();
    for (path, bytes) in files {
        super::write_file(&path, &bytes)?;
        written.push((path, bytes.len() as u64));
    }
    Ok(written)
}
