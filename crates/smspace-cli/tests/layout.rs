//! Arrays saved by NumPy in Fortran order (`np.save(p, np.asfortranarray(a))`, or any
//! transposed array) are read like C-order ones by every command that reads arrays:
//! the same outputs, byte for byte.

mod common;

use std::path::Path;

use ndarray::{Array2, Array3};
use ndarray_npy::{read_npy, write_npy};

use common::ok;

/// Writes `a` as NumPy does for a Fortran-ordered array: `fortran_order: True` in the
/// header, the data with the first index varying fastest.
fn write_fortran<D: ndarray::Dimension>(path: &Path, a: &ndarray::Array<f64, D>) {
    let shape: Vec<String> = a.shape().iter().map(|n| n.to_string()).collect();
    let shape = if shape.len() == 1 {
        format!("({},)", shape[0])
    } else {
        format!("({})", shape.join(", "))
    };
    let mut header = format!("{{'descr': '<f8', 'fortran_order': True, 'shape': {shape}, }}");
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
        bytes.extend_from_slice(&x.to_le_bytes());
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
