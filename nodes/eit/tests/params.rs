//! Reconstructor parameters from TOML: every field by name, defaults, unknown keys rejected,
//! and the adjacent protocol end to end.

use skinflow_eit::{
    CemParams, DifferenceMode, ForwardModel, Mesh, MeshParams, Precision, Prior, ReconParams, Reconstructor, Sensor,
    sensor::PAPER_100MM_TOML,
};

#[test]
fn full_params_parse_and_unknown_keys_fail() {
    let text = r#"
        lambda = 0.05
        mode = "plain"
        image_nx = 32
        image_ny = 48
        precision = "f32"
        cache_dir = "/tmp/eit-cache"
        prior = { laplacian = { epsilon = 0.01 } }
        [mesh]
        elements = 3000
        [cem]
        current_ua = 20.0
        electrode_contact_impedance_ohm_mm2 = []
        [mask]
        saturation_v = 3.3
    "#;
    let p: ReconParams = skinflow_toml::from_str(text).unwrap();
    assert_eq!(p.mode, DifferenceMode::Plain);
    assert_eq!(p.precision, Precision::F32);
    assert_eq!(p.prior, Prior::Laplacian { epsilon: 0.01 });
    assert_eq!(p.mesh.elements, 3000);
    assert_eq!(p.mesh.min_angle_deg, MeshParams::default().min_angle_deg);
    assert_eq!(p.cem.current_ua, 20.0);
    assert_eq!(p.cem.thickness_mm, CemParams::default().thickness_mm);
    let p: ReconParams = skinflow_toml::from_str("prior = { noser = { p = 1.0 } }").unwrap();
    assert_eq!(p.prior, Prior::Noser { p: 1.0 });
    let p: ReconParams = skinflow_toml::from_str(r#"prior = "identity""#).unwrap();
    assert_eq!(p.prior, Prior::Identity);
    let e = skinflow_toml::from_str::<ReconParams>("lamda = 0.1").unwrap_err();
    assert!(e.to_string().contains("lamda"), "{e}");
    let e = skinflow_toml::from_str::<ReconParams>("[mesh]\nelemnts = 3").unwrap_err();
    assert!(e.to_string().contains("elemnts"), "{e}");
    let bad = ReconParams { lambda: -1.0, ..Default::default() };
    let e = Reconstructor::new(&Sensor::paper_100mm(), &bad).err().unwrap();
    assert!(e.to_string().contains("lambda"), "{e}");
}

#[test]
fn reconstructor_is_send() {
    fn send<T: Send + 'static>() {}
    send::<Reconstructor>();
}

#[test]
fn adjacent_protocol_reconstructs_an_inclusion() {
    let s = Sensor::from_toml(&PAPER_100MM_TOML.replace("pairwise", "adjacent")).unwrap();
    let truth = Mesh::generate(&s, &MeshParams { elements: 7000, ..Default::default() }).unwrap();
    let fwd = ForwardModel::new(&s, &truth, &CemParams::default()).unwrap();
    let v_ref = fwd.measure(&fwd.background()).unwrap();
    let c = [-15.0, 20.0];
    let sigma: Vec<f64> = truth
        .element_centroids_mm()
        .iter()
        .map(|p| if (p[0] - c[0]).hypot(p[1] - c[1]) <= 7.5 { 0.01 } else { 0.02 })
        .collect();
    let v = fwd.measure(&sigma).unwrap();
    let mut r = Reconstructor::new(&s, &ReconParams::default()).unwrap();
    assert_eq!(r.measurement_count(), 208);
    let mut img = vec![0.0; r.pixel_count()];
    let mut el = vec![0.0; r.element_count()];
    r.reconstruct_into(&v, &v_ref, &mut img, &mut el).unwrap();
    let k = (0..img.len()).min_by(|&a, &b| img[a].total_cmp(&img[b])).unwrap();
    let peak = r.grid().pixel_centre_mm(k);
    assert!(img[k] < 0.0 && (peak[0] - c[0]).hypot(peak[1] - c[1]) <= 5.0, "{peak:?}");
    assert!(el.iter().all(|x| x.is_finite()));
}

#[test]
fn an_electrode_end_with_three_coordinates_is_refused() {
    // toml alone would read [10.0, -5.0, 3.0] as (10, -5) and drop the third value.
    let text = "[sensor]\nwidth_mm = 20.0\nheight_mm = 10.0\n\
        [[sensor.electrode]]\nstart_mm = [10.0, -5.0, 3.0]\nend_mm = [10.0, 5.0]\n\
        [[sensor.electrode]]\nstart_mm = [-10.0, 5.0]\nend_mm = [-10.0, -5.0]\n\
        [[sensor.electrode]]\nstart_mm = [0.05, 5.0]\nend_mm = [-0.05, 5.0]\n";
    let e = Sensor::from_toml(text).unwrap_err();
    let shown = e.to_string();
    assert!(shown.contains("expected an array of 2 elements, found 3"), "{shown}");
    assert!(shown.contains("line 5, column 12"), "{shown}");
    Sensor::from_toml(&text.replace(", 3.0]", "]")).unwrap();
}
