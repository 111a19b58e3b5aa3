//! Lossy tissue through the main job's path (`probe-bench measure --modulus-kpa E
//! --loss-tangent T --json`, the default method, bench noise, 30 mN): every steady press inside
//! the force window reads within 3 σ and within 2 % of the truth, or is refused as
//! `broad_resonance` — never `bad_contact`, which tissue loss cannot cause when the load cell
//! judges the press; and its loss tangent lies within 3 of its σ of the truth. The truth is the
//! simulated tissue's storage modulus and loss tangent (hal-sim adds the loss as damping through
//! the contact's coupling and leaves the stiffness; the reference phantoms are lossless).

mod common;

fn measure(e_kpa: f64, tan_d: f64, seed: u64) -> serde_json::Value {
    common::run_json(common::bin().args([
        "measure",
        "--json",
        "--modulus-kpa",
        &e_kpa.to_string(),
        "--loss-tangent",
        &tan_d.to_string(),
        "--seed",
        &seed.to_string(),
    ]))
}

#[test]
fn lossy_tissue_reads_within_its_sigma_or_says_the_resonance_is_too_broad() {
    let mut ok = 0;
    let mut broad = 0;
    for (i, e) in [180.0, 420.0, 950.0, 1800.0, 2400.0]
        .into_iter()
        .enumerate()
    {
        for (j, t) in [0.0, 0.12, 0.27, 0.41, 0.5].into_iter().enumerate() {
            let seed = 31 + (5 * i + j) as u64;
            let r = measure(e, t, seed);
            let status = r["status"].as_str().expect("status");
            match status {
                "ok" => {
                    let m = r["modulus_kpa"].as_f64().expect("modulus");
                    let s = r["modulus_sigma_kpa"].as_f64().expect("sigma");
                    assert!((m - e).abs() <= 3.0 * s, "E {e} tan d {t}: {r}");
                    assert!((m / e - 1.0).abs() <= 0.02, "E {e} tan d {t}: {r}");
                    let l = r["loss_tangent"].as_f64().expect("a loss tangent");
                    let sl = r["loss_tangent_sigma"].as_f64().expect("its sigma");
                    assert!(
                        sl > 0.0 && (l - t).abs() <= 3.0 * sl,
                        "E {e} tan d {t}: {r}"
                    );
                    ok += 1;
                }
                "broad_resonance" => {
                    let q = r["q_factor"].as_f64().expect("the Q that was too low");
                    assert!(q < 3.0, "{r}");
                    assert!(t > 0.0, "lossless tissue refused as broad: {r}");
                    broad += 1;
                }
                other => panic!("E {e} tan d {t}: {other}: {r}"),
            }
        }
    }
    // Most of the grid reads; the stiffest, lossiest corner may be refused.
    assert!(ok >= 20, "{ok} ok, {broad} broad");
}
