//! Outliers end to end (issue 12): `simulate --spikes` writes beam breaks
//! into the CSV; `diagnose`, `fit` and `improve` list each with the file
//! line of its row and leave it out; `--keep-outliers` keeps them.

mod common;

use common::{json, run, s, tmp_dir};

fn simulate(dir: &std::path::Path, name: &str, spikes: Option<&str>) -> std::path::PathBuf {
    let csv = dir.join(name);
    let mut args = vec![
        "simulate",
        "--plan",
        "grid:100",
        "line:x:1,bidir",
        "--noise-um",
        "0.15",
        "--seed",
        "4",
        "-o",
        s(&csv),
    ];
    if let Some(sp) = spikes {
        args.extend(["--spikes", sp]);
    }
    common::assert_success(&run(&args));
    csv
}

#[test]
fn spikes_are_reported_with_their_lines_and_left_out() {
    let dir = tmp_dir("outliers_cli", "spikes");
    let clean = simulate(&dir, "clean.csv", None);
    let spiky = simulate(&dir, "spiky.csv", Some("0.005,20"));
    // The spikes' lines: where the two files differ in an error cell (the
    // spike stream is separate, so nothing else moves; the metadata has
    // one more line, `# spikes: …`, so data lines are shifted by one).
    let a = std::fs::read_to_string(&clean).unwrap();
    let b = std::fs::read_to_string(&spiky).unwrap();
    let data_a: Vec<&str> = a.lines().filter(|l| !l.starts_with('#')).collect();
    let first_b = b.lines().position(|l| !l.starts_with('#')).unwrap();
    let mut expected = Vec::new();
    for (k, (la, lb)) in data_a.iter().zip(b.lines().skip(first_b)).enumerate() {
        let (ca, cb): (Vec<&str>, Vec<&str>) = (la.split(',').collect(), lb.split(',').collect());
        for (t, col) in [(0, 3), (1, 4), (2, 5)] {
            if ca[col] != cb[col] {
                expected.push((first_b + k + 1, ["ex", "ey", "ez"][t].to_string()));
            }
        }
    }
    assert!(expected.len() > 10, "{expected:?}");

    let v = json(&run(&[
        "diagnose",
        s(&spiky),
        "--model",
        "cubic19",
        "--json",
    ]));
    let mut found: Vec<(usize, String)> = v["outliers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| {
            (
                o["line"].as_u64().unwrap() as usize,
                o["target"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    found.sort();
    expected.sort();
    assert_eq!(found, expected);
    assert_eq!(v["verdict"], "at_noise_floor", "{}", v["unexplained"]);
    let o = &v["outliers"][0];
    assert!(
        o["resid_um"].as_f64().unwrap().abs() > 15.0 && o["scale_um"].is_number(),
        "{o}"
    );

    // Text: file:line of each.
    let out = run(&["diagnose", s(&spiky), "--model", "cubic19"]);
    let text = String::from_utf8_lossy(&out.stdout);
    let (l, t) = &expected[0];
    assert!(
        text.contains(&format!("{}:{l}: {t} = ", spiky.display())),
        "{text}"
    );

    // fit leaves them out (its RMS is the clean data's), --keep-outliers not.
    let m = dir.join("m.json");
    let f = json(&common::cubic19("fit", &spiky, &m, &[]));
    assert_eq!(f["outliers"].as_array().unwrap().len(), expected.len());
    assert!(f["rms_um"]["ex"].as_f64().unwrap() < 0.2, "{f}");
    let f = json(&common::cubic19("fit", &spiky, &m, &["--keep-outliers"]));
    assert!(f["outliers"].as_array().unwrap().is_empty());
    assert!(f["rms_um"]["ex"].as_f64().unwrap() > 1.0, "{f}");

    // simulate refuses an absurd share, naming the flag.
    let x = dir.join("x.csv");
    let args = [
        "simulate",
        "--plan",
        "grid:100",
        "--spikes",
        "0.5,20",
        "-o",
        s(&x),
    ];
    common::expect_exit(&args, 1, &["--spikes FRAC"]);
    std::fs::remove_dir_all(&dir).unwrap();
}
