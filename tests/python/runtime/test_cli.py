"""The ``dgan`` command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, ROOT, shared_data, zara1_records

import dgan
from dgan.cli import main

SCENE = DATA / "frames_5430_5620.txt"


def test_info(nomap_model: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(nomap_model)]) == 0
    out = capsys.readouterr().out
    assert "observes 8 steps, predicts 12 (4.8 s)" in out
    assert "pedestrian (2 anchors)" in out
    assert "no map branch" in out


def test_info_says_which_map_image_a_mask_model_reads(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", "zara1"]) == 0
    assert "map input  a semantic mask coloured in dgan.scenes.MASK_PALETTE" in capsys.readouterr().out
    assert main(["info", "sdd"]) == 0  # reads its videos' reference photos
    assert "map input" not in capsys.readouterr().out


def test_info_names_contract_9s_temperatures(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", "sdd"]) == 0  # bundled with a speed-dependent and a class temperature
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("temperature"))
    assert "x (1 + speed in m/s)^" in line
    assert "class logits" in line
    assert line.endswith(f"contract {dgan.Predictor('sdd').contract['contract_version']})")  # 9 or later
    assert main(["info", "zara1"]) == 0  # one temperature
    out = capsys.readouterr().out.splitlines()
    line = next(x for x in out if x.startswith("temperature"))
    assert "speed" not in line
    # Contract 10: zara1 declares a denoising gate, sdd none.
    assert any(x.startswith("denoising  ") and ">= 0.1 m" in x for x in out)
    assert main(["info", "sdd"]) == 0
    assert "denoising" not in capsys.readouterr().out


def test_info_names_contract_14s_top_mode_scale(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", "apolloscape"]) == 0  # its cyclists and pedestrians keep part of their top mode's residual
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("top mode"))
    assert "cyclist 0.5, pedestrian 0.25 (contract 14)" in line
    assert main(["info", "zara1"]) == 0
    assert "top mode" not in capsys.readouterr().out


def test_info_names_contract_15s_still_radius(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", "hdmap"]) == 0  # its cyclists' and pedestrians' top mode is held for a still history
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("still"))
    assert "cyclist 0.02 m, pedestrian 0.02 m (contract 15)" in line
    assert main(["info", "zara1"]) == 0
    assert not any(x.startswith("still") for x in capsys.readouterr().out.splitlines())


def test_info_names_contract_16s_top_mean_power(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", "sdd"]) == 0  # its most probable modes are weighted means of its modes
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("top mean"))
    assert "cyclist 8, pedestrian 4, vehicle 2 (contract 16)" in line
    assert main(["info", "zara1"]) == 0
    assert "top mean" not in capsys.readouterr().out


def test_predict_a_real_scene(nomap_model: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", str(nomap_model), str(SCENE), "--time", "5500", "--modes", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("18 agents at time 5500")
    assert "(steps of 0.4 s, horizon 4.8 s)" in out
    lines = out.strip().splitlines()
    assert len(lines) == 20
    # The engine's phases of the call (no map: no crops).
    assert lines[1].startswith("engine: preprocess ")
    assert "network " in lines[1]
    assert lines[1].endswith(" ms")
    assert "crops" not in lines[1]


def test_predict_denoise_smooths_a_noisy_scene_only(
    nomap_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["predict", str(nomap_model), str(SCENE), "--time", "5500", "--json", "--modes", "1"]

    def first_modes(extra: list[str], scene: Path = SCENE, model: str = str(nomap_model)) -> np.ndarray:
        assert main([args[0], model, str(scene), *args[3:], *extra]) == 0
        agents = json.loads(capsys.readouterr().out)["agents"]
        return np.array([a["modes"][0]["trajectory"] for a in agents])

    # The real scene's tracks are clean: --denoise leaves them and the prediction as they were.
    np.testing.assert_array_equal(first_modes(["--denoise"]), first_modes([]))
    # The same scene with 0.3 m of jitter on every position: smoothed, so the prediction changes.
    rows = [line.split() for line in SCENE.read_text().splitlines() if line.strip()]
    rng = np.random.default_rng(0)
    noisy = tmp_path / "noisy.txt"
    noisy.write_text(
        "\n".join(f"{r[0]} {r[1]} {float(r[2]) + rng.normal(0, 0.3)} {float(r[3]) + rng.normal(0, 0.3)}" for r in rows)
    )
    assert not np.array_equal(first_modes(["--denoise", "0.1"], noisy), first_modes([], noisy))
    # zara1 declares the gate (contract 10): it smooths the noisy scene itself, --denoise adds nothing; a wider gate
    # than the model's is named on stderr, since the model's own still applies.
    np.testing.assert_allclose(
        first_modes(["--denoise", "0.1"], noisy, "zara1"), first_modes([], noisy, "zara1"), atol=1e-6
    )
    assert main(["predict", "zara1", str(noisy), *args[3:], "--denoise", "0.3"]) == 0
    assert "leaves no track between 0.1 and 0.3 m as given" in capsys.readouterr().err
    assert main([*args, "--denoise", "-1"]) == 2
    assert "denoising gate" in capsys.readouterr().err


def test_predict_json_and_csv(nomap_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "scene.csv"
    rows = ["agent_id,time,x,y,class"] + [
        f"car-{a},{t * 0.4:.1f},{t * 0.5 + a},{a},pedestrian" for a in range(3) for t in range(8)
    ]
    csv.write_text("\n".join(rows) + "\n")
    assert main(["predict", str(nomap_model), str(csv), "--json", "--modes", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [a["id"] for a in out["agents"]] == ["car-0", "car-1", "car-2"]
    assert out["dt_s"] == 0.4
    assert out["times_s"] == pytest.approx([0.4 * (s + 1) for s in range(12)])
    assert out["current_time"] == pytest.approx(2.8)
    agent = out["agents"][0]
    assert agent["class"] == "pedestrian"
    assert set(agent["class_probabilities"]) == set(dgan.CLASSES)  # the fixture's classes
    assert sum(agent["class_probabilities"].values()) == pytest.approx(1.0)
    assert len(agent["modes"]) == 1
    assert len(agent["modes"][0]["trajectory"]) == 12
    assert agent["modes"][0]["class"] in agent["class_probabilities"]


def test_predict_with_a_map_and_a_table_out(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "modes.csv"
    assert main(["predict", "zara1", str(SCENE), "--time", "5500", "--map", "zara1", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "no --map given" not in err
    lines = out.read_text().splitlines()
    assert lines[0] == "agent_id,mode,probability,class,class_probability,step,time_offset_s,time,x,y"
    assert len(lines) == 1 + 18 * 3 * 12
    assert lines[1].startswith("76,0,")
    assert [line.split(",")[7] for line in lines[1:4]] == ["5510.0", "5520.0", "5530.0"]  # frame ids, as the file
    # The same scene without --map: a note that the model runs without its map, and other predictions.
    assert main(["predict", "zara1", str(SCENE), "--time", "5500", "--out", str(tmp_path / "nomap.parquet")]) == 0
    assert "no --map given; zara1 runs without a map" in capsys.readouterr().err
    import pyarrow.parquet as pq

    table = pq.read_table(tmp_path / "nomap.parquet")
    assert table.num_rows == 18 * 3 * 12
    assert table.column("x").to_pylist()[0] != float(lines[1].split(",")[8])
    # An image map with its homography, and a vector map file.
    scene = ROOT / "python" / "dgan" / "data" / "scenes" / "zara1"
    args = ["predict", "zara1", str(SCENE), "--time", "5500", "--json", "--modes", "1"]
    assert main([*args, "--map", str(scene / "rgb.jpg"), "--pixel-to-world", str(scene / "H.txt")]) == 0
    assert len(json.loads(capsys.readouterr().out)["agents"]) == 18


def test_predict_an_argoverse_scenario_with_its_vector_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 10 Hz Argoverse 2 scenario (never trained on) as a parquet table, its map archive as --map, the 5 Hz hdmap
    model: resampled, predicted with the map, and the same map through dgan's own vector-map JSON."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from dgan.datasets.hdmaps import AV2_SCENARIO_CLASSES, av2_map

    folder = next((shared_data("argoverse2") / "argoverse2" / "motion_forecasting").iterdir())
    src = pq.read_table(next(folder.glob("scenario_*.parquet")))
    keep = pc.is_in(src.column("object_type"), value_set=pa.array(list(AV2_SCENARIO_CLASSES)))
    src = src.filter(keep)
    table = pa.table(
        {
            "agent_id": src.column("track_id"),
            "time": pc.multiply(src.column("timestep").cast(pa.float64()), 0.1),
            "x": src.column("position_x"),
            "y": src.column("position_y"),
            "class": pa.array([AV2_SCENARIO_CLASSES[t] for t in src.column("object_type").to_pylist()]),
        }
    )
    scene = tmp_path / "scenario.parquet"
    pq.write_table(table, scene)
    archive = next(folder.glob("log_map_archive_*.json"))
    outs = []
    own = tmp_path / "map.json"
    dgan.VectorMap(av2_map(archive)).to_json(own)
    for m in (archive, own):
        assert main(["predict", "hdmap", str(scene), "--time", "4.9", "--map", str(m), "--json", "--modes", "2"]) == 0
        outs.append(json.loads(capsys.readouterr().out))
    assert outs[0]["dt_s"] == 0.2
    assert len(outs[0]["agents"]) >= 10
    assert isinstance(outs[0]["agents"][0]["id"], str)
    assert outs[0] == outs[1]
    # Without --map the optional-map model still predicts, and says so; with another map it predicts differently.
    assert main(["predict", "hdmap", str(scene), "--time", "4.9", "--json", "--modes", "2"]) == 0
    captured = capsys.readouterr()
    assert "no --map given" in captured.err
    assert json.loads(captured.out)["agents"] != outs[0]["agents"]


@pytest.mark.slow
def test_models_lists_every_bundled_model(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["models"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:4] == ["model", "dt", "T_obs", "T_f"]
    by_name = {line.split()[0]: line for line in lines[1:]}
    assert set(by_name) == set(dgan.models.list())
    assert "0.5s" in by_name["apolloscape"]
    assert "none" in by_name["apolloscape"]
    assert "vector: HD map" in by_name["hdmap"]
    assert "raster: ETH/UCY scene mask" in by_name["zara1"]
    assert all("non-commercial" in line for line in lines[1:])
    assert main(["models", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["name"]: r["t_f"] for r in rows}["hdmap"] == 15
    assert main(["info", "hdmap"]) == 0
    assert "map kind   vector: HD map" in capsys.readouterr().out


def test_errors_exit_2_with_a_message(nomap_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", str(tmp_path / "none.onnx"), str(SCENE)]) == 2
    assert "model file not found" in capsys.readouterr().err
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2\n3 4\n")
    assert main(["predict", str(nomap_model), str(bad)]) == 2
    assert "nor a known headerless layout: its first row has 2 fields" in capsys.readouterr().err
    # A time that is not in the file: an error naming the span, never "0 agents" and exit 0.
    assert main(["predict", str(nomap_model), str(SCENE), "--time", "5505"]) == 2
    assert "no row at current_time 5505; the table spans 5430..5620" in capsys.readouterr().err
    # A map file that is not a map, an image without its homography.
    junk = tmp_path / "junk.json"
    junk.write_text("{}")
    assert main(["predict", "zara1", str(SCENE), "--map", str(junk)]) == 2
    assert "not a dgan vector map" in capsys.readouterr().err
    assert main(["predict", "zara1", str(SCENE), "--map", "nowhere"]) == 2
    assert "neither a bundled scene" in capsys.readouterr().err
    scene = ROOT / "python" / "dgan" / "data" / "scenes" / "zara1"
    assert main(["predict", "zara1", str(SCENE), "--map", str(scene / "rgb.jpg")]) == 2
    assert "--pixel-to-world" in capsys.readouterr().err
    assert main(["predict", "zara1", str(SCENE), "--out", str(tmp_path / "x.xlsx")]) == 2
    assert "--out must end in" in capsys.readouterr().err


@pytest.mark.slow
def test_demo_faults_fixed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A --time between the excerpt's annotations: a typed error, not an IndexError.
    assert main(["demo", "--time", "5505", "--out", str(tmp_path / "d.png")]) == 2
    assert "no row at current_time 5505" in capsys.readouterr().err
    # At 5510 the excerpt ends 4.4 s later: the true position is the last seen one, said so, not "left the scene".
    assert main(["demo", "--time", "5510", "--out", str(tmp_path / "d.png")]) == 0
    text = capsys.readouterr().out
    assert "left the scene" not in text
    assert "last seen 4.4 s ahead" in text
    # The truth is drawn up to the predicted horizon only.
    from dgan.demo import zara1_scene

    scene = zara1_scene(8, 12, 5430.0 + 70)
    assert max(len(f) for f in scene.futures.values()) == 12


@pytest.mark.parametrize(
    ("model", "expected"),
    [
        ("zara1", "18 agents of zara1 at step 5500"),
        ("sdd", "22 agents of Stanford Drone hyang video0 at step 841"),
        ("apolloscape", "agents of ApolloScape recording 9048 at step 17"),
        ("hdmap", "45 agents of Waymo Open Motion 2bd577a009790706 at step 40"),
    ],
)
@pytest.mark.slow
def test_demo_prints_and_draws(model: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo.png"
    assert main(["demo", "--model", model, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert expected in text
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 50_000
    crop = out.with_name("demo_crop.png")
    has_map = dgan.Predictor(model).spec.map is not None
    assert crop.is_file() == has_map  # one agent's map crop, for the models with a map branch
    if has_map:
        assert "one agent's map crop" in text


def test_demo_needs_only_the_runtime_and_leaves_nothing_tracked(tmp_path: Path) -> None:
    """`./dev demo` installs the runtime's requirements only (no torch), and the demo's pictures are ignored by git."""
    import subprocess

    dev = (ROOT / "dev").read_text()
    assert 'demo) setup runtime; exec "$PY" -m dgan demo' in dev
    runtime = (ROOT / "requirements-runtime.txt").read_text()
    assert "onnxruntime" in runtime
    assert "torch" not in runtime
    for name in ("dgan_demo.png", "dgan_demo_crop.png"):
        ignored = subprocess.run(["git", "check-ignore", "-q", name], cwd=ROOT, check=False)
        assert ignored.returncode == 0, f"{name} is not ignored by git"


@pytest.mark.slow
def test_unreadable_inputs_and_outputs_exit_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = ROOT / "python" / "dgan" / "data" / "scenes" / "zara1"
    notnumbers = tmp_path / "H.txt"
    notnumbers.write_text("a b c\n")
    kept = tmp_path / "kept.csv"
    kept.write_text("kept")
    (tmp_path / "folder.csv").mkdir()
    cases = [
        (["predict", "zara1", "/dev/zero"], "cannot read scene /dev/zero: it is not a regular file"),
        (["predict", "zara1", str(tmp_path / "none.txt")], "it does not exist"),
        (
            ["predict", "zara1", str(SCENE), "--map", str(scene / "rgb.jpg"), "--pixel-to-world", str(notnumbers)],
            "cannot read --pixel-to-world",
        ),
        (
            ["predict", "zara1", str(SCENE), "--map", str(scene / "rgb.jpg"), "--pixel-to-world", str(tmp_path / "no")],
            "cannot read --pixel-to-world",
        ),
        (["predict", "zara1", str(SCENE), "--out", str(tmp_path / "no" / "x.csv")], "cannot write"),
        (["predict", "zara1", str(SCENE), "--out", str(tmp_path / "folder.csv")], "Is a directory"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith("dgan: error: "), err
        assert message in err[-1], err
        assert "Traceback" not in "\n".join(err)
    assert kept.read_text() == "kept"
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "H.txt",
        "folder.csv",
        "kept.csv",
    ]


@pytest.mark.slow
def test_predict_a_directory_or_glob_of_scenes_into_one_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import pyarrow.parquet as pq

    scenes = tmp_path / "scenes"
    scenes.mkdir()
    for name in ("a.txt", "b.txt"):
        (scenes / name).write_text(SCENE.read_text())
    out = tmp_path / "all.parquet"
    assert main(["predict", "zara1", str(scenes), "--out", str(out), "--modes", "2"]) == 0
    table = pq.read_table(out)
    one = dgan.Predictor("zara1", modes=2).predict(
        dgan.Frame.from_records(zara1_records(), spec=dgan.Predictor("zara1"), time_unit=0.04)
    )
    assert table.num_rows == 2 * len(one.to_records()["x"])
    assert table.column_names[0] == "scene"
    assert set(table.column("scene").to_pylist()) == {"a.txt", "b.txt"}
    assert main(["predict", "zara1", str(scenes / "*.txt"), "--out", str(tmp_path / "all.csv")]) == 0
    assert "wrote 28 agents of 2 scenes" in capsys.readouterr().err
    assert main(["predict", "zara1", str(scenes)]) == 2
    assert "need --out" in capsys.readouterr().err


@pytest.mark.slow
def test_predict_options_for_repeated_rows_sparse_data_and_other_classes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rows = ["agent_id,time,x,y,class"]
    for t in np.arange(0.0, 4.01, 0.5):
        rows += [f"1,{t:g},{1.2 * t:g},0,pedestrian", f"2,{t:g},{8 * t:g},5,vehicle"]
    rows.append("1,4,4.8,0.1,pedestrian")  # a repeated row
    path = tmp_path / "street.csv"
    path.write_text("\n".join(rows) + "\n")
    assert main(["predict", "zara1", str(path)]) == 2
    assert "(--duplicates first, last or mean)" in capsys.readouterr().err  # in the command line's words
    assert main(["predict", "zara1", str(path), "--duplicates", "last"]) == 2
    assert "upsampling (--upsample)" in capsys.readouterr().err
    assert main(["predict", "zara1", str(path), "--duplicates", "last", "--upsample"]) == 2
    assert "--unknown-classes ignore predicts" in capsys.readouterr().err
    argv = [
        "predict",
        "zara1",
        str(path),
        "--duplicates",
        "last",
        "--upsample",
        "--unknown-classes",
        "ignore",
        "--json",
    ]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [a["id"] for a in doc["agents"]] == [1]


def _written(path: Path, header: list[str], rows: list[list[str]], sep: str) -> Path:
    path.write_text("\n".join(sep.join(r) for r in [header, *rows]) + "\n")
    return path


def test_predict_reads_a_trackers_table_with_its_own_names_separator_and_times(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = zara1_records()
    seconds = (rec["time"] - rec["time"][0]) * 0.04
    iso = np.datetime_as_string(
        np.datetime64("2026-05-04T10:00:00", "ms") + np.round(seconds * 1e3).astype("timedelta64[ms]"), unit="ms"
    )
    ours = _written(
        tmp_path / "ours.csv",
        ["agent_id", "time", "x", "y"],
        [
            [str(a), f"{t:.2f}", str(float(x)), str(float(y))]
            for a, t, x, y in zip(rec["agent_id"], seconds, rec["x"], rec["y"], strict=True)
        ],
        ",",
    )
    theirs = [
        [f"ped{a}", f"{t}Z", str(float(x)), str(float(y)), "pedestrian", ""]
        for a, t, x, y in zip(rec["agent_id"], iso, rec["x"], rec["y"], strict=True)
    ]
    header = ["Track ID", "timestamp", "pos_x", "pos_y", "type", "note"]
    names = [
        "--column",
        "agent_id=Track ID",
        "--column",
        "time=timestamp",
        "--column",
        "x=pos_x",
        "--column",
        "y=pos_y",
        "--column",
        "class=type",
    ]

    def modes(scene: Path, *options: str) -> list[object]:
        assert main(["predict", "zara1", str(scene), "--json", *options]) == 0, capsys.readouterr().err
        out = json.loads(capsys.readouterr().out)
        return [out["current_time"], [m["trajectory"] for a in out["agents"] for m in a["modes"]]]

    now, expected = modes(ours, "--time", "2.8")
    assert now == 2.8
    for sep in (";", "\t", "|"):
        scene = _written(tmp_path / f"theirs{ord(sep)}.txt", header, theirs, sep)
        assert modes(scene, *names, "--time", "2026-05-04T10:00:02.800") == ["2026-05-04T10:00:02.800", expected]
    assert main(["predict", "zara1", str(scene), *names]) == 0  # the latest time, printed as the file has it
    assert "agents at time 2026-05-04T10:00:07.600," in capsys.readouterr().out
    # Without --column: the option to pass, in the command line's words; an unread column of a known name: a note.
    assert main(["predict", "zara1", str(scene)]) == 2
    assert "did you mean 'Track ID' (--column agent_id=Track ID)?" in capsys.readouterr().err
    assert main(["predict", "zara1", str(scene), *names[:8]]) == 0
    assert (
        "dgan: note: the table has no column 'class' but has 'type', which is not read; pass --column class=type"
        in capsys.readouterr().err
    )
    for bad in ("agent=Track ID", "velocity=vx", "time"):
        assert main(["predict", "zara1", str(scene), "--column", bad]) == 2
        assert "--column takes ARG=NAME with ARG one of agent_id, time, x, y, class" in capsys.readouterr().err
    ragged = _written(
        tmp_path / "ragged.csv", ["agent_id", "time", "x", "y"], [["1", "0", "0", "0"], ["1", "0.4"]], ","
    )
    assert main(["predict", "zara1", str(ragged)]) == 2
    assert "row 2 has 2 fields where the header has 4" in capsys.readouterr().err


def test_a_social_gan_file_in_scientific_notation_is_no_header(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = zara1_records()
    scene = tmp_path / "sci.txt"
    scene.write_text(
        "".join(
            f"{t:.6e}\t{a:.1e}\t{x:.9e}\t{y:.9e}\n"
            for t, a, x, y in zip(rec["time"], rec["agent_id"], rec["x"], rec["y"], strict=True)
        )
    )
    assert main(["predict", "zara1", str(scene), "--time", "5500", "--json"]) == 0
    sci = json.loads(capsys.readouterr().out)
    assert main(["predict", "zara1", str(SCENE), "--time", "5500", "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert [a["id"] for a in sci["agents"]] == [a["id"] for a in plain["agents"]]
    np.testing.assert_allclose(
        [m["trajectory"] for a in sci["agents"] for m in a["modes"]],
        [m["trajectory"] for a in plain["agents"] for m in a["modes"]],
        atol=1e-5,
    )


def test_a_reader_that_stops_early_is_no_error(tmp_path: Path) -> None:
    import subprocess
    import sys

    scene = tmp_path / "many.csv"
    scene.write_text(
        "agent_id,time,x,y\n" + "".join(f"{a},{k * 0.4:.1f},{k * 0.5},{a}\n" for a in range(3000) for k in range(8))
    )
    run = subprocess.run(
        f"{sys.executable} -m dgan predict zara1 {scene} | head -n 1",
        shell=True,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.stdout.startswith("3000 agents at time 2.8")
    assert "rror" not in run.stderr, run.stderr


def test_a_photo_as_the_map_of_a_mask_model_warns_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    scene = ROOT / "python" / "dgan" / "data" / "scenes" / "zara1"
    photo = ["--map", str(scene / "rgb.jpg"), "--pixel-to-world", str(scene / "H.txt")]
    assert main(["predict", "zara1", str(SCENE), "--time", "5500", *photo]) == 0
    err = capsys.readouterr().err.splitlines()
    assert [line for line in err if "warning" in line.lower()] == [
        next(line for line in err if line.startswith("dgan: warning: zara1.onnx reads its map as a semantic mask"))
    ]
    assert main(["predict", "zara1", str(SCENE), "--time", "5500", "--map", "zara1"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_a_spreadsheets_csv_with_a_byte_order_mark_and_crlf_reads_as_any(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rows = ["agent_id,time,x,y"] + [f"{a},{t * 0.4:.1f},{t * 0.5 + a},{a}" for a in range(3) for t in range(8)]
    plain, excel = tmp_path / "plain.csv", tmp_path / "excel.csv"
    plain.write_text("\n".join(rows) + "\n")
    excel.write_bytes(b"\xef\xbb\xbf" + ("\r\n".join(rows) + "\r\n").encode())
    outs = []
    for scene in (plain, excel):
        assert main(["predict", "zara1", str(scene), "--json"]) == 0, capsys.readouterr().err
        outs.append(json.loads(capsys.readouterr().out))
    assert outs[0] == outs[1]
    assert [a["id"] for a in outs[1]["agents"]] == [0, 1, 2]


def test_predict_reads_a_trackers_labels_as_asked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = ["agent_id,time,x,y,class"] + [
        f"{a},{t * 0.2:.1f},{t * 0.3},{4 * a},{label}" for a, label in enumerate(["car", "Person"]) for t in range(10)
    ]
    scene = tmp_path / "labels.csv"
    scene.write_text("\n".join(rows) + "\n")
    assert main(["predict", "hdmap", str(scene)]) == 2
    assert "'car' is no dgan class" in (err := capsys.readouterr().err)
    assert "--common-classes reads it as 'vehicle' (or map your labels yourself: --class-name car=CLASS)" in err
    for options in (["--common-classes"], ["--class-name", "car=vehicle", "--class-name", "person=pedestrian"]):
        assert main(["predict", "hdmap", str(scene), "--json", *options]) == 0
        assert [a["class"] for a in json.loads(capsys.readouterr().out)["agents"]] == ["vehicle", "pedestrian"]
    assert main(["predict", "hdmap", str(scene), "--class-name", "car"]) == 2
    assert "--class-name takes LABEL=CLASS" in capsys.readouterr().err


def test_predict_at_every_time_of_a_scene_into_one_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import pyarrow.parquet as pq

    out = tmp_path / "every.parquet"
    assert main(["predict", "zara1", str(SCENE), "--every", "--map", "zara1", "--modes", "2", "--out", str(out)]) == 0
    assert "at 20 times" in capsys.readouterr().err  # frames 5430..5620 every 10
    table = pq.read_table(out).to_pandas()
    first_steps = table[table["step"] == 1]
    assert sorted(first_steps["time"].unique()) == [5440.0 + 10 * k for k in range(20)]
    # The rows predicted from 5500 are what --time 5500 predicts.
    at = table[(table["time"] - table["time_offset_s"] / 0.04).round(6) == 5500.0]
    one = tmp_path / "one.parquet"
    assert (
        main(["predict", "zara1", str(SCENE), "--time", "5500", "--map", "zara1", "--modes", "2", "--out", str(one)])
        == 0
    )
    alone = pq.read_table(one).to_pandas()
    assert len(at) == len(alone) == 18 * 2 * 12
    np.testing.assert_allclose(at[["x", "y"]].to_numpy(), alone[["x", "y"]].to_numpy(), atol=1e-6)
    capsys.readouterr()
    assert main(["predict", "zara1", str(SCENE), "--every"]) == 2
    assert "--every needs --out TABLE" in capsys.readouterr().err


def test_evaluate_prints_the_table_writes_targets_and_draws(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, chart = tmp_path / "targets.csv", tmp_path / "chart.png"
    args = ["evaluate", "zara1", str(SCENE), "--map", "zara1", "--modes", "5", "--out", str(out)]
    assert main([*args, "--plot", str(chart), "--plot-horizon", str(tmp_path / "horizon.png")]) == 0
    printed = capsys.readouterr()
    assert "zara1: 14 targets at 1 times" in printed.out
    assert "min5 ADE/FDE" in printed.out
    assert "wrote 14 targets" in printed.err
    header, *lines = out.read_text().splitlines()
    assert header.startswith("time,agent_id,class,moving,ade,fde,min5_ade")
    assert len(lines) == 14
    assert chart.stat().st_size > 10_000
    assert (tmp_path / "horizon.png").stat().st_size > 10_000
    expected = dgan.evaluate("zara1", zara1_records(), time_unit=0.04, map=dgan.scene_map("zara1"), modes=5)
    assert main(["evaluate", "zara1", str(SCENE), "--map", "zara1", "--modes", "5", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert rows[0]["ade"] == pytest.approx(expected.rows()[0]["ade"], abs=1e-12)


def test_evaluate_pools_scenes_and_speaks_the_command_lines_words(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for name in ("a.txt", "b.txt"):
        (tmp_path / name).write_text(SCENE.read_text())
    assert main(["evaluate", "univ", str(tmp_path), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["scenes"] == ["a.txt", "b.txt"]
    assert got["rows"][0]["targets"] == 28
    assert main(["evaluate", "hdmap", str(SCENE)]) == 2  # 2.5 Hz data for a 5 Hz model
    assert "--upsample" in capsys.readouterr().err
    assert main(["evaluate", "zara1", str(SCENE), "--stride", "0"]) == 2
    assert "stride must be" in capsys.readouterr().err
