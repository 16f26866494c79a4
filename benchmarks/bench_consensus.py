"""The takes' consensus against the truth, from a finished run (issue #34).

``.venv/bin/python benchmarks/bench_consensus.py RUN [subject ...]`` reads each synthetic
subject's store (``RUN/results/{subject}/{subject}.h5``) and truth, and prints for every take the
consensus registered (``/consensus``'s ``takes``):

- the error of the raw motion (aligned mesh minus the neutral's, no mask, no smoothing) against
  the material motion of the skin, as a share of its RMS, of the take's refined mesh
  (``/takes/{take}/refine/vertices``) and of its consensus mesh
  (``/takes/{take}/consensus/vertices``), over the vertices valid in both;
- the **mean-error oracle**: what perfect take-to-take flows would leave, every member's error
  along the surface replaced by the members' mean one (its error along the normal kept), from the
  truth; the consensus cannot see the mean error, so this is its floor;
- the consensus's ``confident_share`` and ``median_correction_px``.

A subject without a consensus prints why (``/consensus``'s ``problem``). Nothing is asserted;
the printed table is the measurement (default cohort, 2026-12-06, synth02's ten takes: the
expressions reach their oracle, sad1 0.779 -> 0.425 (0.413), frown1 0.585 -> 0.343 (0.353); the
visemes stay 0.03-0.05 above it, man 0.269 -> 0.189 (0.141), she 0.399 -> 0.299 (0.269)).
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import h5py
import numpy as np

from scan2morph.evaluate.motion import template_lip_sides, true_motions
from scan2morph.evaluate.truth import read_truth
from scan2morph.geometry import vertex_normals
from scan2morph.store import paths, read_part


def subject_table(run: Path, subject: str) -> list[str]:
    """The printed lines of one subject."""
    store_path = run / "results" / subject / f"{subject}.h5"
    with h5py.File(store_path) as h5:
        attrs = dict(h5[paths.CONSENSUS].attrs) if paths.CONSENSUS in h5 else {}
    members = json.loads(attrs.get("takes", "[]"))
    if not members:
        return [f"{subject}: no consensus ({attrs.get('problem', 'a store before the stage')})"]
    store = read_part(store_path)
    truth_dir = run / "results" / "synthetic" / subject / "truth"
    truths = {t: read_truth(truth_dir / f"{t}.npz") for t in ["neutral", *members]}
    neutral = store[paths.mesh("neutral", "vertices")]
    normals = vertex_normals(neutral, store[paths.template("faces")])
    sides = template_lip_sides(store[paths.template("vertices2d")])
    material = true_motions(neutral, truths["neutral"], {t: truths[t] for t in members}, sides)

    def along(d):
        return d - np.einsum("ij,ij->i", d, normals)[:, None] * normals

    errors = {
        t: (
            store[paths.refine(t, "vertices")] - neutral - material[t],
            store[paths.consensus(t, "vertices")] - neutral - material[t],
        )
        for t in members
    }
    with warnings.catch_warnings():  # a vertex no member has: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        mean_along = np.nanmean([along(e[0]) for e in errors.values()], axis=0)
    lines = [f"{subject}: {len(members)} takes; raw material error refined -> consensus (oracle)"]
    with h5py.File(store_path) as h5:
        for take, (refined, moved) in errors.items():
            ok = np.isfinite(refined).all(1) & np.isfinite(moved).all(1)
            ok &= np.isfinite(material[take]).all(1) & np.isfinite(mean_along).all(1)
            ref = np.sum(material[take][ok] ** 2)

            def share(d, ok=ok, ref=ref):
                return float(np.sqrt(np.sum(d[ok] ** 2) / ref))

            oracle = refined - along(refined) + mean_along
            report = dict(h5[paths.consensus_group(take)].attrs)
            lines.append(
                f"  {take:8s} {share(refined):.3f} -> {share(moved):.3f} ({share(oracle):.3f})"
                f"  confident {report['confident_share']:.2f}, median move "
                f"{report['median_correction_px']:.2f} px"
            )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a finished run's working directory")
    ap.add_argument("subjects", nargs="*", default=["synth01", "synth02", "synth03", "synth04"])
    args = ap.parse_args()
    for subject in args.subjects:
        print("\n".join(subject_table(args.run, subject)))


if __name__ == "__main__":
    main()
