"""Several runs of one configuration (seeds) as one exported model: :class:`training.model.ConsensusEnsemble`.

    python -m training.ensemble RUN [RUN ...] --out model.onnx [--checkpoint ensemble.pt] [--name NAME]

Each RUN is a ``training.train`` output folder (its ``best.pt``). The model keeps the contract of a single run: the
engine runs it unchanged, with every member inside one ONNX graph (so a call costs about the members' count times one
network). Its most probable mode (of the agent's most probable class) is the mean of the members' most probable
modes; the other modes are the first member's. The temperature is fitted anew on the validation split
(``training.calibrate``; ``--no-calibrate`` keeps the first member's), since the consensus mode is the best mode more
often than any one member's top mode.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import torch

from training.calibrate import calibrate_checkpoint
from training.export import SLIM_KEYS, export_checkpoint, load_checkpoint


def ensemble_checkpoint(runs: list[Path], out: Path, half: bool = False) -> Path:
    """Writes the checkpoint of the runs' ensemble (their ``best.pt``, slimmed) to ``out``. With ``half`` the weights
    are rounded to float16 and kept so (the exported file then stores them as float16 too: half the size of both,
    the same arithmetic in the engine and in PyTorch)."""
    members: list[dict[str, Any]] = []
    for run in runs:
        ckpt = torch.load(run / "best.pt", weights_only=False)
        member = {k: ckpt[k] for k in SLIM_KEYS if k in ckpt}
        if half:
            member["model"] = {k: v.half() if v.is_floating_point() else v for k, v in member["model"].items()}
        members.append(member)
    out.parent.mkdir(parents=True, exist_ok=True)
    first_t = float(members[0].get("temperature", 1.0))
    torch.save({"members": members, "runs": [r.name for r in runs], "temperature": first_t}, out)
    load_checkpoint(out)  # the members must share inputs and classes
    return out


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True, help="the ONNX model to write")
    ap.add_argument("--checkpoint", type=Path, help="also keep the ensemble's checkpoint here (for parity tests)")
    ap.add_argument("--name", default="dgan-ensemble")
    ap.add_argument("--description", default="")
    ap.add_argument("--data-root", type=Path, help="the data folder for the validation split (the runs' own if unset)")
    ap.add_argument("--no-calibrate", action="store_true", help="keep the first member's temperature")
    ap.add_argument("--half", action="store_true", help="round the weights to float16 and store them so")
    a = ap.parse_args(argv)
    missing = [str(r) for r in a.runs if not (r / "best.pt").is_file()]
    if missing:
        ap.error(f"not training runs (no best.pt): {', '.join(missing)}")
    with tempfile.TemporaryDirectory() as tmp:
        ckpt = ensemble_checkpoint(a.runs, a.checkpoint or Path(tmp) / "ensemble.pt", a.half)
        if not a.no_calibrate:
            print(calibrate_checkpoint(ckpt, a.data_root, progress=True))
        description = a.description or f"Consensus of {len(a.runs)} runs: {', '.join(r.name for r in a.runs)}"
        path = export_checkpoint(ckpt, a.out, a.name, description)
    print(f"exported {path}")
    return path


if __name__ == "__main__":
    main()
