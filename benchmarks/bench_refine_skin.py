"""The refinement's parameters on real skin: the real head smiling, over many draws of the clicks.

The scene is ``tests/unit/test_realdata.py``'s :func:`skin_scene`: the real head scan (Lee
Perry-Smith, CC BY 3.0, read from ``../shared/data``) in a front view and smiling (cheeks 5 mm
up and out, mouth corners 6 mm) seen 4 degrees aside and 2 above in a 15% dimmer light; the
template is a 3 px grid over the face in the front view, the fit a thin-plate spline through
clicks at least 45 px apart with 0.5 px of noise, drawn ``--draws`` times (seeded). For the
config's ``refine`` parameters and each ``--params`` set it prints, over the interior (12 px in
from the grid's edge), the mean over the draws of the RMS error, its median and 90th
percentile (px), the worst draw's RMS, and the confident share; the fit's first.

Run: ``.venv/bin/python benchmarks/bench_refine_skin.py [--draws 6] [--params
iterations=2,high_pass_px=4,smooth_px=4 ...]`` (each set overrides the config's).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import yaml

from scan2morph.stages import refine as refine_stage

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "unit"), str(ROOT)]
from test_realdata import (  # noqa: E402  (the scene lives with the tests)
    _MISSING,
    DATA_DIR,
    SEED,
    load_head,
    skin_errors,
    skin_scene,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=ROOT / "config" / "config.yaml")
    ap.add_argument("--draws", type=int, default=6)
    ap.add_argument("--params", nargs="*", default=["iterations=2,high_pass_px=4,smooth_px=4"])
    args = ap.parse_args()
    if _MISSING:
        print(f"skipped: the real head scan is absent ({DATA_DIR} lacks {', '.join(_MISSING)})")
        return
    config = yaml.safe_load(args.config.read_text())
    base = refine_stage.Params.from_config(config).flow
    sets = {"config": base}
    for text in args.params:
        change = {k: yaml.safe_load(v) for k, v in (kv.split("=") for kv in text.split(","))}
        sets[text] = dataclasses.replace(base, **change)
    scene = skin_scene(load_head())
    seeds = [SEED + 7 + k for k in range(args.draws)]
    rows: dict[str, list[dict]] = {name: [] for name in sets}
    for seed in seeds:
        for name, params in sets.items():
            rows[name].append(skin_errors(scene, seed, params))
    print(
        f"\n{args.draws} draws of the clicks (seeds {seeds[0]}-{seeds[-1]}), "
        f"{int(scene.inner.sum())} interior points; px, mean over the draws"
    )
    print(f"{'parameters':45s} {'RMS':>6s} {'median':>7s} {'p90':>6s} {'worst':>6s} {'conf':>5s}")
    for name in ["fit", *sets]:
        key = "fit" if name == "fit" else "refined"
        r = rows["config" if name == "fit" else name]
        m = {s: np.mean([x[f"{key}_{s}"] for x in r]) for s in ("rms", "median", "p90")}
        worst = max(x[f"{key}_rms"] for x in r)
        conf = "" if name == "fit" else f"{np.mean([x['confident_share'] for x in r]):5.2f}"
        print(f"{name:45s} {m['rms']:6.3f} {m['median']:7.3f} {m['p90']:6.3f} {worst:6.3f} {conf}")


if __name__ == "__main__":
    main()
