//! Predict every pedestrian of a real ETH/UCY scene with a dgan model, as a Rust service would.
//!
//! ```text
//! ORT_DYLIB_PATH=/abs/path/libonnxruntime.so.1.23.2 \
//!   cargo run -p dgan-core --release --example predict -- [MODEL.onnx] [SCENE.txt] [T_OBS_FRAME]
//! ```
//!
//! Defaults: the bundled `zara1` model (trained without the zara1 scene; run here without its map, which it takes as
//! optional) and the bundled zara1 excerpt (`python/dgan/data/zara1`), predicting from frame 5500.
//! The scene file is in the Social-GAN layout (`frame ped_id x y`, metres, 0.4 s steps).

use dgan_core::{frame_at, tracks_from_rows, AgentClass, Detection, Predictor, Result, TimeBase};
use std::path::PathBuf;

fn repo(rel: &str) -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .map_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")), PathBuf::from)
        .join("../..")
        .join(rel)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let model = args.get(1).map(PathBuf::from).unwrap_or_else(|| repo("python/dgan/models/zara1.onnx"));
    let scene = args.get(2).map(PathBuf::from).unwrap_or_else(|| repo("python/dgan/data/zara1/frames_5430_5620.txt"));
    let t_obs_frame: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(5500.0);

    let predictor = Predictor::load(&model)?;
    let spec = &predictor.contract().input;
    let text = std::fs::read_to_string(&scene)
        .map_err(|e| dgan_core::DganError::InvalidFrame(format!("cannot read {}: {e}", scene.display())))?;
    // Each row a detection (frame ids step by 10, 0.4 s); the engine groups them into tracks and resamples them onto
    // the model's grid as `dgan.Frame.from_records` does.
    let seconds_per_frame_id = 0.04;
    let mut rows = Vec::new();
    for line in text.lines() {
        let v: Vec<f64> = line.split_whitespace().filter_map(|s| s.parse().ok()).collect();
        if let [frame, ped, x, y] = v[..] {
            rows.push((ped as i64, Detection::at(frame * seconds_per_frame_id, x, y)));
        }
    }
    let tracks = tracks_from_rows(rows)?;
    let views: Vec<(i64, &[Detection])> = tracks.iter().map(|(id, t)| (*id, t.as_slice())).collect();
    let base = TimeBase::new(spec.t_obs, spec.dt_s)?;
    let frame = frame_at(&views, t_obs_frame * seconds_per_frame_id, &base, AgentClass::Pedestrian)?;
    let n = frame.len();
    let started = std::time::Instant::now();
    let prediction = predictor.predict_modes(&frame, 3)?;
    let elapsed = started.elapsed();
    println!(
        "model {} | {n} agents at frame {t_obs_frame} | {} attention edges | predict took {elapsed:.2?}",
        model.display(),
        prediction.edges.nrows()
    );
    for (i, id) in prediction.agent_ids.iter().enumerate() {
        let modes: Vec<String> = (0..prediction.probabilities.ncols())
            .map(|m| {
                let last = prediction.trajectories.dim().2 - 1;
                let (x, y) = (prediction.trajectories[[i, m, last, 0]], prediction.trajectories[[i, m, last, 1]]);
                format!("p={:.3} → ({x:.2}, {y:.2})", prediction.probabilities[[i, m]])
            })
            .collect();
        println!("agent {id:>4}: {}", modes.join(" | "));
    }
    Ok(())
}
