"""The bundled models, their cards and scene maps."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

import dgan
from dgan import exceptions as exc

SCENES = ("eth", "hotel", "univ", "zara1", "zara2")


@pytest.mark.slow
def test_five_leave_one_out_models_are_bundled() -> None:
    assert set(SCENES) <= set(dgan.models.list())
    for name in SCENES:
        p = dgan.Predictor(name)
        assert p.spec.t_obs == 8
        assert p.spec.t_f == 12
        assert p.classes == ("pedestrian",)
        assert p.anchors["pedestrian"].shape == (20, 12, 2)
        assert p.spec.map is not None
        card = dgan.models.card(name)
        assert f"test scene {name}" in card
        assert "non-commercial" in card
        assert dgan.models.path(name).stat().st_size < size_limit(card)


@pytest.mark.parametrize(
    ("name", "dt", "t_obs", "t_f", "has_map", "k_c"),
    [("sdd", 1 / 3, 8, 12, True, 20), ("apolloscape", 0.5, 6, 6, False, 20), ("hdmap", 0.2, 10, 15, True, 10)],
)
def test_multiclass_models_are_bundled(name: str, dt: float, t_obs: int, t_f: int, has_map: bool, k_c: int) -> None:
    p = dgan.Predictor(name)
    assert p.classes == dgan.CLASSES
    assert p.spec.dt_s == pytest.approx(dt)
    assert (p.spec.t_obs, p.spec.t_f) == (t_obs, t_f)
    assert (p.spec.map is not None) == has_map
    for cls in p.classes:
        assert p.anchors[cls].shape == (k_c, t_f, 2)
    assert p.num_modes == 3 * k_c
    card = dgan.models.card(name)
    assert "one model for vehicles, cyclists and pedestrians" in card
    assert "non-commercial" in card
    assert dgan.models.path(name).stat().st_size < size_limit(card)


def size_limit(card: str) -> int:
    """A bundled network stays under 5 MB; an ensemble (its card says of how many runs, float16 weights) under 2 MB
    a member."""
    found = re.search(r"\*\*Ensemble\*\*: the consensus of (\d+) runs", card)
    return 5_000_000 if found is None else 2_000_000 * int(found.group(1))


def test_unknown_names_list_the_bundled_ones() -> None:
    with pytest.raises(exc.ModelNotFoundError, match="zara1"):
        dgan.Predictor("zara9")
    with pytest.raises(exc.ModelNotFoundError):
        dgan.models.card("nope")


@pytest.mark.slow
def test_scene_maps_match_their_models(zara1_frame: dgan.Frame) -> None:
    m = dgan.scene_map("zara1")
    assert m.image.shape == (576, 720, 3)
    # Colourised mask: only palette colours.
    colours = np.unique(m.image.reshape(-1, 3), axis=0)
    assert all(any((c == p).all() for p in dgan.scenes.MASK_PALETTE) for c in colours)
    with pytest.raises(exc.InvalidMapError, match="bundled scenes"):
        dgan.scene_map("times_square")
    frame = dgan.Frame(zara1_frame.positions, mask=zara1_frame.mask, ids=zara1_frame.ids, map=m)
    pred = dgan.Predictor("zara1", modes=5).predict(frame)
    assert pred.trajectories.shape == (len(frame), 5, 12, 2)
    # Pedestrians walk: the most likely mode ends within 15 m of where each one is now.
    dist = np.linalg.norm(pred.most_likely[:, -1] - frame.positions[:, -1], axis=1)
    assert np.all(dist < 15.0)


@pytest.mark.parametrize("name", ["zara1", "sdd", "apolloscape", "hdmap"])
def test_a_bundled_model_beats_standing_still(name: str) -> None:
    """On its bundled real excerpt, a bundled model's top mode is far closer to what happened than standing still."""
    predictor = dgan.Predictor(name)
    scene = dgan.demo.scene_for(predictor.spec)
    pred = predictor.predict(scene.frame)
    errs, still = [], []
    for i, pid in enumerate(scene.frame.ids):
        fut = scene.futures[int(pid)]
        if len(fut) == predictor.spec.t_f:
            errs.append(np.linalg.norm(pred.most_likely[i] - fut, axis=1).mean())
            still.append(np.linalg.norm(scene.frame.positions[i, -1] - fut, axis=1).mean())
    assert len(errs) >= 2  # ApolloScape tracks are short: 2 of its excerpt's agents stay for all 3 s
    assert np.mean(errs) < 0.5 * np.mean(still)


#: Bundled models that still move a perfectly still lone agent of some class by more than 0.05 m (issue 25); strict,
#: so the mark must go when they no longer do. `hdmap` moved a still vehicle 1.12 m before its standing prior;
#: `apolloscape` 0.08 / 0.05 / 0.11 m before its held copy and top-mode scale (2026-12-06: 0.035 / 0.013 / 0.031).
STILL_AGENT_FAILS: dict[tuple[str, str], float] = {}
#: The same on the model's bundled demo scene's map, placed where each of its agents was last seen: the map moves a
#: still agent of the classes that read it. Worst over the placements, metres. `hdmap`'s cyclists (0.18) stay put
#: since its cyclists' still radius (contract 15, chosen on validation: `training.still`) and its pedestrians (0.094,
#: 0.133 with their mean top mode) since their radius passed validation under that decoding (runs/RULES-2026-12-06r);
#: `eth` (0.0549) and `zara2` (0.0995) since 2026-12-07, whose best radius (0.05 m) passed the engine on validation
#: though under `training.still`'s 2% bar (runs/RULES-2026-12-07d).
STILL_ON_MAP_FAILS: dict[tuple[str, str], float] = {}


#: Every bundled model and class, each model loaded once for the tests parametrised by them.
MODEL_CLASSES = [(name, klass) for name in dgan.models.list() for klass in dgan.Predictor(name).classes]


def by_class(fails: dict[tuple[str, str], float]) -> list[Any]:
    """Every bundled model and class, those of ``fails`` as strict expected failures naming how far they move."""
    return [
        pytest.param(
            name,
            klass,
            marks=[pytest.mark.xfail(strict=True, reason=f"moves it {fails[name, klass]} m")]
            if (name, klass) in fails
            else [],
        )
        for name, klass in MODEL_CLASSES
    ]


def moved(predictor: dgan.Predictor, klass: str, at: npt.NDArray[np.float64], scene_map: Any = None) -> float:
    """How far the most probable mode moves one agent of ``klass`` that stood still at ``at`` all its history."""
    here = np.broadcast_to(at, (1, predictor.spec.t_obs, 2)).copy()
    top = predictor.predict(dgan.Frame(here, classes=[klass], map=scene_map)).trajectories[0, 0]
    return float(np.linalg.norm(top - at, axis=-1).max())


@pytest.mark.parametrize(("name", "klass"), by_class(STILL_AGENT_FAILS))
def test_a_perfectly_still_lone_agent_stays_put(name: str, klass: str) -> None:
    predictor = dgan.Predictor(name)
    if predictor.spec.map is not None and not predictor.spec.map.optional:
        pytest.skip("the model needs its map")
    assert moved(predictor, klass, np.array([10.0, 5.0])) <= 0.05


@pytest.mark.parametrize(("name", "klass"), by_class(STILL_ON_MAP_FAILS))
def test_a_perfectly_still_lone_agent_stays_put_on_its_map(name: str, klass: str) -> None:
    predictor = dgan.Predictor(name)
    frame = dgan.demo.scene_for(predictor.spec).frame
    if frame.map is None:
        pytest.skip("no map in the model's demo scene")
    seen = [frame.positions[i, -1] for i in range(len(frame)) if frame.mask[i, -1]]
    assert max(moved(predictor, klass, at, frame.map) for at in seen) <= 0.05


#: A georeferenced origin (UTM-like metres): the whole scene, agents and map, moved this far from its own coordinates.
FAR = np.array([512345.678, 4123456.789])


def grid_pitch_m(spec: dgan.InputSpec) -> float | None:
    """The pitch of the grid fixed in the world on which a model's map inputs are computed (docs/model-contract.md):
    a kept-features model's feature pitch (``stride`` pixels; its tiles' halo makes their features independent of
    where a tile ends), a tiled map's tile side (128 pixels of half the crop's: the tiles are drawn clipped to their
    own bounds); None for a crop drawn per agent, in the agent's own frame."""
    m = spec.map
    if m is None or (m.scene is None and m.render != "tiles"):
        return None
    return m.scene.stride * m.resolution_m if m.scene is not None else 128 * m.resolution_m / 2


@pytest.mark.parametrize("name", dgan.models.list())
def test_a_scene_far_from_the_origin_is_predicted_as_near_it(name: str) -> None:
    """Georeferenced coordinates (millions of metres) lose nothing: every bundled model predicts its demo scene, map
    included, moved 4,000 km away as it predicts it where it is. A model whose map is read on a grid fixed in the
    world is moved by a whole number of that grid's pitch: by anything else its inputs are the map drawn at another
    phase of the grid (docs/model-contract.md, *The map's grid and the world's origin*)."""
    predictor = dgan.Predictor(name)
    frame = dgan.demo.scene_for(predictor.spec).frame
    pitch = grid_pitch_m(predictor.spec)
    shift = FAR if pitch is None else np.round(FAR / pitch) * pitch
    here, far = predictor.predict(frame), dgan.Predictor(name).predict(frame.moved(shift))
    np.testing.assert_allclose(far.trajectories - shift, here.trajectories, rtol=0, atol=1e-4)
    np.testing.assert_allclose(far.probabilities, here.probabilities, rtol=0, atol=1e-5)
