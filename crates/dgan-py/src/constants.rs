//! `dgan._dgan.CONTRACT`: what the engine owns about the model contract, for Python, training and the tests to
//! derive from instead of typing it again (classes, map kinds with their colours, widths and drawing order, feature
//! columns, tensor names, versions).

use dgan_core::contract as c;
use dgan_core::map::PALETTE;
use dgan_core::{raster, AgentClass};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The contract's constants as a dict of plain Python values (see `_dgan.pyi` for the keys).
pub(crate) fn contract(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("version", c::CONTRACT_VERSION)?;
    d.set_item("supported_versions", c::SUPPORTED_CONTRACT_VERSIONS.to_vec())?;
    d.set_item("raster_version", raster::RASTER_VERSION)?;
    d.set_item("preprocess_version", dgan_core::preprocess::PREPROCESS_VERSION)?;
    d.set_item("metadata_key", c::METADATA_KEY)?;
    d.set_item("classes", AgentClass::ALL.map(AgentClass::name).to_vec())?;
    let sizes = PyDict::new(py);
    for class in AgentClass::ALL {
        sizes.set_item(class.name(), (class.default_length_m(), class.default_width_m()))?;
    }
    d.set_item("class_sizes_m", sizes)?;
    let kinds = PALETTE.map(|style| -> PyResult<Bound<'_, PyDict>> {
        let k = PyDict::new(py);
        k.set_item("name", style.name)?;
        k.set_item("polygon", style.polygon)?;
        k.set_item("colour", rgb(style.colour))?;
        k.set_item("width_m", (!style.polygon).then_some(style.width_m))?;
        Ok(k)
    });
    d.set_item("map_kinds", kinds.into_iter().collect::<PyResult<Vec<_>>>()?)?;
    d.set_item("agent_colour", rgb(raster::AGENT))?;
    d.set_item("state_features", dgan_core::spec::STATE_FEATURES.to_vec())?;
    d.set_item("edge_features", dgan_core::spec::EDGE_FEATURES.to_vec())?;
    d.set_item("state_mirrored", dgan_core::spec::STATE_MIRRORED.to_vec())?;
    d.set_item("edge_mirrored", dgan_core::spec::EDGE_MIRRORED.to_vec())?;
    let inputs = PyDict::new(py);
    for layout in ["edge_list", "padded"] {
        inputs.set_item(layout, all_inputs(layout, "").map_err(crate::error::to_py)?)?;
    }
    // A scene model whose features are kept with the map (contract 13).
    let kept = r#", "tile_px": 4, "halo_px": 0, "channels": 1"#;
    inputs.set_item("kept", all_inputs("padded", kept).map_err(crate::error::to_py)?)?;
    d.set_item("inputs", inputs)?;
    d.set_item("outputs", [c::OUTPUT_CLASS_LOGITS, c::OUTPUT_ANCHOR_LOGITS, c::OUTPUT_OFFSETS].to_vec())?;
    d.set_item("kept_output", c::OUTPUT_MAP_FEATURES)?;
    Ok(d)
}

/// Every input a model of a graph layout can take (with a map that may be absent, read as a scene; `kept` more keys
/// of its scene), in the contract's order.
fn all_inputs(layout: &str, kept: &str) -> dgan_core::Result<Vec<&'static str>> {
    let json = format!(
        r#"{{"dt_s": 1, "t_obs": 2, "t_f": 2, "classes": ["pedestrian"], "attention_lambda": 0, "graph": "{layout}",
            "map": {{"height_px": 2, "width_px": 2, "resolution_m": 1, "agent_row": 1, "agent_col": 1, "optional": true,
                     "draw_agents": false, "scene": {{"min_px": 4, "stride": 1{kept}}}}}}}"#
    );
    let spec = crate::preprocess::parse_spec(&json)?;
    Ok(c::expected_inputs(&spec).into_iter().map(|t| t.name).collect())
}

/// A colour as a tuple of three integers (a `Vec<u8>` would reach Python as bytes).
fn rgb([r, g, b]: raster::Rgb) -> (u8, u8, u8) {
    (r, g, b)
}
