//! Arrays saved by NumPy in Fortran order (`np.save(p, np.asfortranarray(a))`, or any
//! transposed array) are read like C-order ones by every command that reads arrays:
//! the same outputs, byte for byte.

mod common;

use std::path::Path;

use ndarray::{Array2, Array3};
use ndarray_npy::{read_npy, write_npy};

use common::ok;

/// An element NumPy writes as 8 little-endian bytes.
trait Element: Copy {
    const DESCR: &'static str;
    fn bytes(self) -> [u8; 8];
}

impl Element for f64 {
    const DESCR: &'static str = "<f8";
    fn bytes(self) -> [u8; 8] {
        self.to_le_bytes()
    }
}

impl Element for i64 {
    const DESCR: &'static str = "<i8";
    fn bytes(self) -> [u8; 8] {
        self.to_le_bytes()
    }
}

/// Writes `a` as NumPy does for a Fortran-ordered array: `fortran_order: True` in the
/// header, the data with the first index varying fastest.
fn write_fortran<T: Element, D: ndarray::Dimension>(path: &Path, a: &ndarray::Array<T, D>) {
    let shape: Vec<String> = a.shape().iter().map(|n| n.to_string()).collect();
    let shape = if shape.len() == 1 {
        format!("({},)", shape[0])
    } else {
        format!("({})", shape.join(", "))
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': True, 'shape': {shape}, }}",
        T::DESCR
    );
    // Magic (6) + version (2) + length (2) + header + newline: a multiple of 64.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    // The reversed-axes view in logical order is the array in Fortran order.
    for x in a.view().reversed_axes().iter() {
        bytes.extend_from_slice(&x.bytes());
    }
    std::fs::write(path, bytes).unwrap();
}

fn write_fortran_2(path: &Path, a: &Array2<f64>) {
    write_fortran(path, a);
    // The file reads back as the same array (ndarray-npy honours the flag).
    let back: Array2<f64> = read_npy(path).unwrap();
    assert_eq!(&back, a);
}

fn write_fortran_3(path: &Path, a: &Array3<f64>) {
    write_fortran(path, a);
    let back: Array3<f64> = read_npy(path).unwrap();
    assert_eq!(&back, a);
}

fn same_file(dir: &Path, a: &str, b: &str) {
    assert_eq!(
        std::fs::read(dir.join(a)).unwrap(),
        std::fs::read(dir.join(b)).unwrap(),
        "{a} and {b} differ"
    );
}

#[test]
fn fortran_order_inputs_give_the_same_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "explore",
            "--agent",
            "planar-arm",
            "--n",
            "40",
            "--seed",
            "2",
            "--out-dir",
            ".",
        ],
    );
    let motors: Array2<f64> = read_npy(d.join("motors.npy")).unwrap();
    write_fortran_2(&d.join("motors-f.npy"), &motors);
    for (motors, out) in [("motors.npy", "sets.npy"), ("motors-f.npy", "sets-f.npy")] {
        ok(
            d,
            &[
                "trace",
                "--agent",
                "planar-arm",
                "--motors",
                motors,
                "--points",
                "20",
                "--out",
                out,
            ],
        );
    }
    same_file(d, "sets.npy", "sets-f.npy");

    let sets: Array3<f64> = read_npy(d.join("sets.npy")).unwrap();
    write_fortran_3(&d.join("sets-f.npy"), &sets);
    for (sets, out) in [("sets.npy", "D.npy"), ("sets-f.npy", "D-f.npy")] {
        ok(d, &["distances", "--sets", sets, "--out", out]);
    }
    same_file(d, "D.npy", "D-f.npy");

    let distances: Array2<f64> = read_npy(d.join("D.npy")).unwrap();
    write_fortran_2(&d.join("D-f.npy"), &distances);
    // The poses of the traced rows, in both orders.
    let poses: Array2<f64> = read_npy(d.join("poses.npy")).unwrap();
    let kept: ndarray::Array1<i64> = read_npy(d.join("sets.kept.npy")).unwrap();
    let rows: Vec<usize> = kept.iter().map(|&k| k as usize).collect();
    let poses = poses.select(ndarray::Axis(0), &rows);
    write_npy(d.join("poses-c.npy"), &poses).unwrap();
    write_fortran_2(&d.join("poses-f.npy"), &poses);
    for method in ["mds", "cca", "isomap"] {
        for (input, out) in [("D.npy", "Y.npy"), ("D-f.npy", "Y-f.npy")] {
            ok(
                d,
                &[
                    "embed",
                    "--distances",
                    input,
                    "--method",
                    method,
                    "--dim",
                    "2",
                    "--out",
                    out,
                ],
            );
        }
        same_file(d, "Y.npy", "Y-f.npy");
    }
    for (input, poses, out) in [
        ("D.npy", "poses-c.npy", "a.json"),
        ("D-f.npy", "poses-f.npy", "a-f.json"),
    ] {
        ok(
            d,
            &[
                "analyze",
                "--distances",
                input,
                "--poses",
                poses,
                "--out",
                out,
            ],
        );
    }
    same_file(d, "a.json", "a-f.json");
}

/// The inputs not covered above, in Fortran order: the kNN lists and the sets of
/// `distances --knn` and `--tile`, `embed --extend` and a kNN graph, `invariance`'s
/// motors. Every output equals the one from C-order inputs, byte for byte.
#[test]
fn fortran_order_inputs_of_every_other_reader() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "explore",
            "--agent",
            "planar-arm",
            "--n",
            "30",
            "--seed",
            "3",
            "--out-dir",
            ".",
        ],
    );
    ok(
        d,
        &[
            "trace",
            "--agent",
            "planar-arm",
            "--motors",
            "motors.npy",
            "--points",
            "16",
            "--out",
            "sets.npy",
        ],
    );
    let sets: Array3<f64> = read_npy(d.join("sets.npy")).unwrap();
    write_fortran_3(&d.join("sets-f.npy"), &sets);
    std::fs::copy(d.join("sets.closed.npy"), d.join("sets-f.closed.npy")).unwrap();
    std::fs::create_dir(d.join("c")).unwrap();
    std::fs::create_dir(d.join("f")).unwrap();
    for (input, folder) in [("sets.npy", "c"), ("sets-f.npy", "f")] {
        let out = format!("{folder}/D.npy");
        ok(
            d,
            &["distances", "--sets", input, "--knn", "4", "--out", &out],
        );
        let tile = format!("{folder}/T.npy");
        ok(
            d,
            &[
                "distances",
                "--sets",
                input,
                "--metric",
                "curve",
                "--tile",
                "0:9,5:20",
                "--out",
                &tile,
            ],
        );
    }
    for file in [
        "knn_indices.npy",
        "knn_distances.npy",
        "T.npy",
        "T.tile.json",
    ] {
        same_file(d, &format!("c/{file}"), &format!("f/{file}"));
    }
    // Isomap from the kNN lists in both orders.
    let indices: Array2<i64> = read_npy(d.join("c/knn_indices.npy")).unwrap();
    let distances: Array2<f64> = read_npy(d.join("c/knn_distances.npy")).unwrap();
    write_fortran(&d.join("f/knn_indices.npy"), &indices);
    write_fortran_2(&d.join("f/knn_distances.npy"), &distances);
    for folder in ["c", "f"] {
        let (i, k, y) = (
            format!("{folder}/knn_indices.npy"),
            format!("{folder}/knn_distances.npy"),
            format!("{folder}/Yk.npy"),
        );
        ok(
            d,
            &[
                "embed",
                "--knn-indices",
                &i,
                "--knn-distances",
                &k,
                "--method",
                "isomap",
                "--k",
                "4",
                "--dim",
                "2",
                "--out",
                &y,
            ],
        );
    }
    same_file(d, "c/Yk.npy", "f/Yk.npy");
    // Out-of-sample points: their distances to the embedded sets, in both orders.
    ok(d, &["distances", "--sets", "sets.npy", "--out", "D.npy"]);
    let full: Array2<f64> = read_npy(d.join("D.npy")).unwrap();
    let new_to_old = full
        .slice_axis(ndarray::Axis(0), ndarray::Slice::from(0..5))
        .to_owned();
    write_npy(d.join("c/new.npy"), &new_to_old).unwrap();
    write_fortran_2(&d.join("f/new.npy"), &new_to_old);
    for folder in ["c", "f"] {
        for method in ["mds", "cca"] {
            let (new, y) = (
                format!("{folder}/new.npy"),
                format!("{folder}/Y-{method}.npy"),
            );
            ok(
                d,
                &[
                    "embed",
                    "--distances",
                    "D.npy",
                    "--method",
                    method,
                    "--dim",
                    "2",
                    "--extend",
                    &new,
                    "--out",
                    &y,
                ],
            );
        }
    }
    same_file(d, "c/Y-mds.extended.npy", "f/Y-mds.extended.npy");
    same_file(d, "c/Y-cca.extended.npy", "f/Y-cca.extended.npy");
    // Invariance from motors in both orders.
    let motors: Array2<f64> = read_npy(d.join("motors.npy")).unwrap();
    let motors = motors
        .slice_axis(ndarray::Axis(0), ndarray::Slice::from(0..12))
        .to_owned();
    write_npy(d.join("c/motors.npy"), &motors).unwrap();
    write_fortran_2(&d.join("f/motors.npy"), &motors);
    for folder in ["c", "f"] {
        let (m, out) = (format!("{folder}/motors.npy"), format!("{folder}/inv.json"));
        ok(
            d,
            &[
                "invariance",
                "--agent",
                "planar-arm",
                "--motors",
                &m,
                "--env-seeds",
                "1,2",
                "--points",
                "16",
                "--out",
                &out,
            ],
        );
    }
    for file in [
        "inv.json",
        "inv-D-1.npy",
        "inv-D-2.npy",
        "inv-sensors-2.npy",
    ] {
        same_file(d, &format!("c/{file}"), &format!("f/{file}"));
    }
}
