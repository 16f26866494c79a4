"""The click-noise error bar's estimators against the truth, draw by draw (issue #35).

Run after ``make run``: ``.venv/bin/python benchmarks/bench_noise_estimators.py [--out F.json]
[--realisations 8] [subject ...]`` (default synth01, synth02, synth04; synth03 has no exact 2D
landmarks to draw around and is skipped). For each subject it makes ``REALISATIONS`` (or
``--realisations``) fresh draws of the nominal click noise (``synthetic.scanner.click_noise_px``)
around the exact landmarks (seed ``SEED``: the clicks of ``bench_motion_noise.py``'s error-bar
check), re-runs fit, align, refine and motion of the neutral and the visemes (``sweep``'s
stages, the run's config) for each and for the exact landmarks, and measures

* the truth: the click-noise part of the motion error, both as ``bench_motion_noise.py`` takes
  it, ``sqrt(mean(rel^2) - rel0^2)`` with ``rel`` the realisations' ``relative_error`` and
  ``rel0`` the exact clicks' (``bench``), and directly (``direct``): the RMS over realisations of
  the RMS over the unmasked vertices of the final motion minus the exact clicks' final motion,
  over the RMS of the motion there, which is what the error bar claims to be;
* on every realisation, the error bar's draws as the stage makes them (its streams, seed and
  click noise, :func:`scan2morph.motion.uncertainty.click_noise_motion`): per draw the mean over
  the unmasked vertices of the squared change of the refined final motion (``REFINED`` draws)
  and of the fit-only final motion (``FIT_DRAWS``, the first ``REFINED`` with the same clicks),
  with Gaussian clicks (the stage's) and with random signs (``+-px`` per coordinate, the same
  variance).

It prints, per viseme, the truth and each estimator of :data:`ESTIMATORS`: today's (the 4
refined draws), 2 refined draws, 2 with the fit-only draws as a ratio control variate (times the
fit-only draws' mean over all 16 over their mean over those 2), and 4 and 2 sign draws; each as
its mean over the realisations and (in brackets) the RMS of log(error bar / direct truth) over
realisations and disjoint draw sets. ``--out F.json`` keeps the draws, ``--report F.json``
prints their table again.

``--paired [VARIANT ...] [--run RUN] [--draws 4] [subject ...]`` runs the stage's refined draws
(its clicks) on a finished run's parts with the config's ``refine`` and with each variant of
its flow settings (``flow_level=1``, ``iterations=3``, ...): per viseme each one's error bar,
its ratio to the config's and the correlation of the draws (the same clicks), their CPU, and
the share of the refined change per vertex that the fit-only change explains.

Measured (2026-12-05, the default config's run of be09376, 8 realisations of 0.5 px; about 25
min on 2 cores shared with other work): mean error bar over the realisations (RMS log of error
bar / direct truth)::

    subject vis   bench direct      4 draws      2 draws   2 + fit CV       4 sign       2 sign
    synth01 car   0.000  0.053 0.042 (0.26) 0.041 (0.33) 0.041 (0.35) 0.040 (0.32) 0.039 (0.36)
    synth01 man   0.000  0.022 0.024 (0.14) 0.024 (0.15) 0.023 (0.17) 0.025 (0.16) 0.025 (0.17)
    synth01 she   0.000  0.039 0.037 (0.12) 0.037 (0.14) 0.039 (0.15) 0.040 (0.10) 0.040 (0.11)
    synth01 eel   0.000  0.036 0.031 (0.16) 0.031 (0.17) 0.031 (0.22) 0.037 (0.11) 0.037 (0.12)
    synth01 too   0.000  0.036 0.034 (0.06) 0.034 (0.10) 0.038 (0.11) 0.037 (0.08) 0.037 (0.09)
    synth02 car   0.000  0.017 0.023 (0.57) 0.021 (0.55) 0.022 (0.55) 0.031 (0.74) 0.028 (0.66)
    synth02 man   0.079  0.042 0.039 (0.11) 0.039 (0.17) 0.037 (0.18) 0.036 (0.18) 0.036 (0.23)
    synth02 she   0.000  0.115 0.119 (0.14) 0.118 (0.18) 0.121 (0.22) 0.121 (0.12) 0.121 (0.16)
    synth02 eel   0.104  0.165 0.153 (0.30) 0.151 (0.37) 0.148 (0.39) 0.172 (0.35) 0.171 (0.36)
    synth02 too   0.117  0.123 0.125 (0.19) 0.124 (0.22) 0.139 (0.30) 0.118 (0.14) 0.116 (0.21)
    synth04 car   0.000  0.075 0.071 (0.41) 0.070 (0.46) 0.074 (0.41) 0.070 (0.38) 0.070 (0.42)
    synth04 man   0.139  0.139 0.164 (0.27) 0.154 (0.56) 0.146 (0.59) 0.162 (0.35) 0.155 (0.62)
    synth04 she   0.000  0.060 0.063 (0.10) 0.062 (0.13) 0.065 (0.18) 0.067 (0.14) 0.066 (0.16)
    synth04 eel   0.031  0.047 0.045 (0.09) 0.045 (0.10) 0.044 (0.13) 0.047 (0.09) 0.047 (0.12)
    synth04 too   0.039  0.055 0.059 (0.12) 0.059 (0.14) 0.065 (0.22) 0.061 (0.11) 0.061 (0.13)
    all: rms log                   (0.24)       (0.30)       (0.31)       (0.28)       (0.32)
    all: mean log                   -0.03        -0.06        -0.04        +0.02        -0.01

Today's estimator tracks the direct truth (mean log -0.03: 3% low; RMS log 0.06-0.57 per
viseme, the heavy-tailed ones, synth02 car and synth04 car and man, worst). The bench's
difference of squares is no measure of it: the click error is not orthogonal to the error the
exact clicks leave, and the difference is zero (negative) on 9 of the 15 visemes. Halving the
refined draws (the CPU needed for synth02's and synth03's subject jobs under 30 s) loosens the
tracking 0.24 -> 0.30; the fit-only draws do not win it back as a control variate (0.31), nor do
sign clicks (0.32; with 4 draws 0.28). Within a realisation a draw's refined and fit-only mean
squared changes correlate with a median r of 0.46 (-0.17 to 0.86): a control variate removes
r^2 of the variance (a median 21%), where halving the draws doubles it (r^2 >= 0.5 would be
needed; 1 viseme of 15 has it). ``--paired`` on synth02 shows why: the fit-only change explains
1-23% of the refined change per vertex (car 0.01, man 0.11, she 0.23, eel 0.14, too 0.17), the
refined change being the refinement's own response to the moved clicks (flow, lips, jaw), not
the fit's slide passed through. Cheaper refinements in the draws move the error bar
itself (ratio to the config's on the same clicks, synth02, 4 draws; CPU-s of the draws 24.9):
``flow_level=1`` 1.11-1.38 (16.1 CPU-s), ``iterations=3`` 1.01-1.19 (20.7), ``iterations=2``
1.18-1.83 (15.3), and OpenCV's FAST preset for the flow (patched in, not a config key) 0.85-1.15
(20.8, correlation 0.47-0.96). Warm starts were not tried: in the linear regime a draw's
deviation from the nominal refinement decays by the same factor per round whether the round
starts from the fit or from the nominal result, so they cannot stand in for rounds. None was
adopted; the stage is unchanged.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from scan2morph.errors import InputError
from scan2morph.evaluate.truth import read_truth
from scan2morph.motion.clicks import clicked_take
from scan2morph.motion.uncertainty import (
    ClickNoise,
    DrawRecipe,
    _corresponded,
    _FinalMotion,
    _fit,
    _perturbed,
)
from scan2morph.refine.memo import sharing
from scan2morph.stages import Run, Subject, accuracy, motion_noise
from scan2morph.stages.quality import modelled
from scan2morph.store import paths, read_attrs, read_part, read_parts
from scan2morph.sweep import _MODULES, sweep_settings
from scan2morph.template import load_template

ROOT = Path(__file__).resolve().parents[1]
REALISATIONS = 8
SEED = 7
#: Refined draws per realisation (the old estimator's 4), fit-only draws.
REFINED = 4
FIT_DRAWS = 16
#: The config's motion_noise.seed (the stage's streams).
SEED_NOISE = 2009


def upstream(store, run: Run, landmarks) -> dict:
    """The store with these clicks, re-run through fit, align, refine and motion."""
    drop = paths.written_by(paths.STAGES[paths.STAGES.index("fit") :])
    data = {k: v for k, v in store.items() if not drop.match(k)}
    data |= {paths.landmarks(t): x for t, x in landmarks.items()}
    for name in ("fit", "align", "refine", "motion"):
        data |= _MODULES[name].apply(data, run)
    return data


def signs(rng, shape) -> np.ndarray:
    """Random signs (+-1) of ``shape``: Rademacher click noise, unit variance per coordinate."""
    return rng.integers(0, 2, shape) * 2.0 - 1.0


def fit_recipe(params: motion_noise.Params) -> DrawRecipe:
    """The stage's recipe of a draw's fit (its rules and rim share; no refiner: the refined
    draws call the stage's refiner themselves)."""
    return DrawRecipe(params.fit.rules, params.smoothing, None, params.fit.rim_share)


def partners_of(neutral, n_fits) -> list:
    """Each draw's neutral with that draw's clicks, whose rim a viseme's fit of the same draw
    follows (as :func:`scan2morph.motion.uncertainty.click_noise_motion` pairs them)."""
    return [neutral if f is None else replace(neutral, landmarks=f[2]) for f in n_fits]


def perturbed(
    template, c, stream, px, n, recipe, sign: bool, seed: int = SEED_NOISE, partners=None
) -> list:
    """``n`` fits of a take with its clicks perturbed (Gaussian, or +-px with ``sign``), the
    stage's streams (:func:`scan2morph.motion.uncertainty._perturbed`); None where a fit is
    refused. ``partners``: each draw's neutral (a viseme's)."""
    if not sign:
        fits, _ = _perturbed(
            template, "t", c, stream, ClickNoise(px, n, seed), n, recipe, "s", partners
        )  # fmt: skip
        return fits
    rng = np.random.default_rng([seed, *stream])
    out = []
    for k in range(n):
        noisy = c.landmarks + px * signs(rng, np.shape(c.landmarks))
        partner = None if partners is None else partners[k]
        try:
            out.append((*_fit(template, c, noisy, recipe, "t", partner), noisy))
        except InputError:
            out.append(None)
    return out


def draws(template, data, run: Run, px: float, seed: int = SEED_NOISE) -> dict:
    """Per viseme and noise kind (``gauss``, ``sign``): the refined and fit-only draws' mean
    squared change over the unmasked vertices (lists, mm^2), and the motion's RMS there."""
    subject = run.subject
    params = motion_noise.Params.from_config(run.config)
    verdicts = motion_noise.shape_verdicts(data, subject.visemes)
    refiner = motion_noise._refiner(template, subject, data, params.refine, verdicts)
    fiducials = {t: params.fit.fiducial_set(k) for t, k in subject.kinds.items()}
    takes = {t: clicked_take(data, t, fiducials[t]) for t in [subject.neutral, *subject.visemes]}
    suppressed = np.asarray(data[paths.mask("suppressed")], dtype=bool)
    smooth = _FinalMotion(suppressed, params.smoothing)
    recipe = fit_recipe(params)
    neutral = takes[subject.neutral]
    n_base, n_mesh = _fit(template, neutral, neutral.landmarks, recipe, "n")
    faces = n_mesh["faces"]
    out = {v: {} for v in subject.visemes}
    with sharing():
        for kind in ("gauss", "sign"):
            sign = kind == "sign"
            n_fits = perturbed(template, neutral, [0], px, FIT_DRAWS, recipe, sign, seed)
            partners = partners_of(neutral, n_fits)
            for take in subject.visemes:
                c = takes[take]
                ref = np.asarray(c.motion, dtype=np.float64)
                t0 = _fit(template, c, c.landmarks, recipe, take, neutral)
                ref_fit = smooth(t0[0], t0[1]["valid"], None, n_base, n_mesh["valid"], faces, take)
                stream = [1, zlib.crc32(take.encode())]
                t_fits = perturbed(template, c, stream, px, FIT_DRAWS, recipe, sign, seed, partners)
                free = ~suppressed & np.isfinite(ref).all(axis=1)
                rec = {
                    "refined": [],
                    "fit": [],
                    "motion_rms_mm": float(np.sqrt(np.mean(np.sum(ref[free] ** 2, axis=1)))),
                }
                for k, (nf, tf) in enumerate(zip(n_fits, t_fits, strict=True)):
                    if nf is None or tf is None:  # a refused draw, as the stage leaves it out
                        continue
                    nv = nf[1]["valid"]
                    m = smooth(tf[0], tf[1]["valid"], None, nf[0], nv, faces, take)
                    rec["fit"].append(float(np.nanmean(np.sum((m - ref_fit) ** 2, axis=1)[free])))
                    if k < REFINED:
                        v, valid, conf = _corresponded(refiner, take, tf, tf[2], nf[2])
                        m = smooth(v, valid, conf, nf[0], nv, faces, take)
                        d2 = np.sum((m - ref) ** 2, axis=1)[free]
                        rec["refined"].append(float(np.nanmean(d2)))
                out[take][kind] = rec
    return out


def measure(subject: str, realisations: int = REALISATIONS) -> dict:
    """Truth and draws of one subject (see the module's docstring) over ``realisations``."""
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    nominal = float(config["synthetic"]["scanner"]["click_noise_px"])
    rows = config["synthetic"]["takes"]
    kinds = {t["take"]: t["kind"] for t in rows}
    labels = {t["take"]: t["label"] for t in rows}
    keep = {t: k for t, k in kinds.items() if k in ("neutral", "viseme")}
    template = load_template(ROOT / "resources" / "template.npz")
    settings = sweep_settings(config, {})
    settings["motion_noise"]["click_noise_px"] = nominal
    store = read_part(ROOT / "results" / subject / f"{subject}.h5")
    run = Run(Subject(subject, keep, {t: labels[t] for t in keep}), template, settings)
    truths = {
        t: read_truth(ROOT / "results" / "synthetic" / subject / "truth" / f"{t}.npz")
        for t in kinds
    }
    visemes = [t for t, k in keep.items() if k == "viseme"]
    acc_params = accuracy.Params.from_config(settings)
    mine = {t: truths[t] for t in keep}

    def rel(data):
        acc = accuracy.run(
            template, run.subject, data | accuracy.truth_datasets(mine), acc_params
        ).files["accuracy"]
        return {v: acc["takes"][v]["motion"]["relative_error"] for v in visemes}

    if not all(np.isfinite(truths[t].landmarks2d).all() for t in keep):
        print(f"{subject}: no exact 2D landmarks (no click noise to draw around): skipped")
        return {}
    exact = upstream(store, run, {t: truths[t].landmarks2d for t in keep})
    rel0 = rel(exact)
    free = ~np.asarray(exact[paths.mask("suppressed")], dtype=bool)
    rng = np.random.default_rng(SEED)
    out = {"rel0": rel0, "realisations": []}
    for r in range(realisations):
        t0 = time.perf_counter()
        clicks = {
            t: truths[t].landmarks2d + nominal * rng.standard_normal(truths[t].landmarks2d.shape)
            for t in kinds
        }
        data = upstream(store, run, {t: clicks[t] for t in keep})
        direct = {}
        for v in visemes:
            m, m0 = data[paths.viseme(v, "motion")], exact[paths.viseme(v, "motion")]
            ok = free & np.isfinite(m).all(axis=1) & np.isfinite(m0).all(axis=1)
            direct[v] = float(
                np.sqrt(np.mean(np.sum((m - m0)[ok] ** 2, axis=1)))
                / np.sqrt(np.mean(np.sum(m[ok] ** 2, axis=1)))
            )
        entry = {"rel": rel(data), "direct": direct, "draws": draws(template, data, run, nominal)}
        out["realisations"].append(entry)
        print(f"{subject} realisation {r}: {time.perf_counter() - t0:.0f} s", flush=True)
    return out


#: The estimators compared: name -> (noise kind, the refined draws each estimate uses (disjoint
#: sets: one estimate each per realisation), whether the fit-only draws scale it).
ESTIMATORS = {
    "4 draws": ("gauss", [slice(0, 4)], False),
    "2 draws": ("gauss", [slice(0, 2), slice(2, 4)], False),
    "2 + fit CV": ("gauss", [slice(0, 2), slice(2, 4)], True),
    "4 sign": ("sign", [slice(0, 4)], False),
    "2 sign": ("sign", [slice(0, 2), slice(2, 4)], False),
}


def error_bar(rec: dict, part: slice, control: bool) -> float:
    """A viseme's relative error bar from the refined draws ``part`` of one realisation; with
    ``control``, times the fit-only draws' mean over all of them over their mean over ``part``
    (the ratio control variate)."""
    x, y = np.asarray(rec["refined"]), np.asarray(rec["fit"])
    ms = x[part].mean() * (y.mean() / y[part].mean() if control else 1.0)
    return float(np.sqrt(ms) / rec["motion_rms_mm"])


def report(results: dict) -> None:
    """Per viseme: the truth (the bench's definition, direct) and each estimator's mean over
    the realisations with, in brackets, the RMS over realisations (and disjoint draw sets) of
    log(error bar / direct truth); last, that RMS and the mean log over every viseme."""
    print(
        f"\n{'subject':8}{'vis':5}{'bench':>6} {'direct':>6} "
        + " ".join(f"{k:>12}" for k in ESTIMATORS)
    )
    logs = {k: [] for k in ESTIMATORS}
    for subject, res in results.items():
        if not res:
            continue
        real = res["realisations"]
        for v, r0 in res["rel0"].items():
            rels = [r["rel"][v] for r in real]
            bench = np.sqrt(max(np.mean(np.square(rels)) - r0**2, 0.0))
            direct = np.sqrt(np.mean([r["direct"][v] ** 2 for r in real]))
            cells = []
            for k, (kind, parts, control) in ESTIMATORS.items():
                bars = np.array(
                    [error_bar(r["draws"][v][kind], p, control) for r in real for p in parts]
                )
                lr = np.log(bars / direct)
                logs[k].append(lr)
                cells.append(f"{bars.mean():.3f} ({np.sqrt(np.mean(lr**2)):.2f})")
            print(
                f"{subject:8}{v:5}{bench:6.3f} {direct:6.3f} " + " ".join(f"{c:>12}" for c in cells)
            )
    rms = [np.sqrt(np.mean(np.concatenate(x) ** 2)) for x in logs.values()]
    print(f"{'all: rms log':25}" + " ".join(f"{f'({r:.2f})':>12}" for r in rms))
    bias = [np.mean(np.concatenate(x)) for x in logs.values()]
    print(f"{'all: mean log':25}" + " ".join(f"{f'{b:+.2f}':>12}" for b in bias))


def paired(run_dir: Path, subject: str, variants: list[str], n: int) -> None:
    """``--paired``: the stage's refined draws (its clicks, seed and click noise) on a finished
    run's parts, once with the config's ``refine`` and once per variant (``key=value[+...]``
    over ``refine``'s flow settings, e.g. ``flow_level=1``, ``iterations=3``): per viseme the
    error bar (mm) and, per variant, its ratio to the config's and the correlation of the
    draws' log mean squared change; the CPU seconds of each; last, the share of the config's
    refined change per vertex that the fit-only draws' change explains (least squares, one
    factor per viseme: what a per-vertex control variate could remove)."""
    config = yaml.safe_load((run_dir / "config" / "config.yaml").read_text())
    rows = config["synthetic"]["takes"]
    kinds = {t["take"]: t["kind"] for t in rows}
    takes = [t for t, k in kinds.items() if k in ("neutral", "viseme")]
    res = run_dir / "results" / subject
    files = [res / "takes" / t / f"{p}.h5" for t in takes for p in ("repair", "landmarks")]
    files += [res / "takes" / t / "align.h5" for t in takes if kinds[t] == "viseme"]
    files += [res / "consensus.h5"] if (res / "consensus.h5").exists() else []  # the draws' moves
    data = read_parts(files) | read_part(res / "motion.h5")
    data |= {
        paths.refine_group(t): read_attrs(res / "takes" / t / "refine.h5", paths.refine_group(t))
        for t in takes
        if kinds[t] == "viseme"
    }
    px = float(read_part(res / "motion_noise.h5")[paths.motion_noise("click_noise_px")])
    template = load_template(run_dir / "resources" / "template.npz")
    params = motion_noise.Params.from_config(config)
    subj = modelled(Subject(subject, kinds, {t["take"]: t["label"] for t in rows}), data)
    ct = {t: clicked_take(data, t, params.fit.fiducial_set(kinds[t])) for t in takes}
    suppressed = np.asarray(data[paths.mask("suppressed")], dtype=bool)
    smooth = _FinalMotion(suppressed, params.smoothing)
    recipe = fit_recipe(params)
    neutral = ct[subj.neutral]
    n_fits = perturbed(template, neutral, [0], px, n, recipe, False)
    partners = partners_of(neutral, n_fits)
    t_fits = {
        v: perturbed(
            template, ct[v], [1, zlib.crc32(v.encode())], px, n, recipe, False, partners=partners
        )
        for v in subj.visemes
    }
    runs, changes = {}, {}
    for variant in ["config", *variants]:
        p = params.refine
        for kv in variant.split("+") if variant != "config" else []:
            key, value = kv.split("=")
            p = replace(p, flow=replace(p.flow, **{key: type(getattr(p.flow, key))(value)}))
        verdicts = motion_noise.shape_verdicts(data, subj.visemes)
        refiner = motion_noise._refiner(template, subj, data, p, verdicts)
        c0, x = time.process_time(), {}
        with sharing():
            for v in subj.visemes:
                ref = np.asarray(ct[v].motion, dtype=np.float64)
                free = ~suppressed & np.isfinite(ref).all(axis=1)
                x[v] = []
                for nf, tf in zip(n_fits, t_fits[v], strict=True):
                    if nf is None or tf is None:
                        continue
                    vv, valid, conf = _corresponded(refiner, v, tf, tf[2], nf[2])
                    m = smooth(vv, valid, conf, nf[0], nf[1]["valid"], nf[1]["faces"], v)
                    x[v].append(float(np.nanmean(np.sum((m - ref) ** 2, axis=1)[free])))
                    if variant == "config":
                        changes.setdefault(v, []).append(m - ref)
        runs[variant] = x
        cells = " ".join(f"{v} {np.sqrt(np.mean(x[v])):.3f}" for v in x)
        print(f"{variant:24} cpu {time.process_time() - c0:5.1f} s  error bar mm: {cells}")
    for variant in variants:
        cells = " ".join(
            f"{v} {np.sqrt(np.mean(runs[variant][v]) / np.mean(runs['config'][v])):.2f} "
            f"(r {np.corrcoef(np.log(runs[variant][v]), np.log(runs['config'][v]))[0, 1]:.2f})"
            for v in subj.visemes
        )
        print(f"{variant:24} ratio to the config's (correlation): {cells}")
    n0, m0 = _fit(template, neutral, neutral.landmarks, recipe, "n")
    shares = []
    for v in subj.visemes:
        t0 = _fit(template, ct[v], ct[v].landmarks, recipe, v, neutral)
        base = smooth(t0[0], t0[1]["valid"], None, n0, m0["valid"], m0["faces"], v)
        e = np.array(
            [
                smooth(tf[0], tf[1]["valid"], None, nf[0], nf[1]["valid"], m0["faces"], v) - base
                for nf, tf in zip(n_fits, t_fits[v], strict=True)
                if nf is not None and tf is not None
            ]
        )
        d = np.array(changes[v])
        ok = ~suppressed & np.isfinite(d).all(axis=(0, 2)) & np.isfinite(e).all(axis=(0, 2))
        d, e = d[:, ok], e[:, ok]
        beta = np.sum(d * e) / np.sum(e * e)
        shares.append(f"{v} {1 - np.sum((d - beta * e) ** 2) / np.sum(d * d):.2f}")
    print("share of the refined change the fit-only change explains: " + " ".join(shares))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("subjects", nargs="*")
    parser.add_argument("--out", type=Path, help="keep the draws here (JSON)")
    parser.add_argument("--report", type=Path, help="only report these kept draws")
    parser.add_argument("--paired", nargs="*", metavar="VARIANT", help="see paired()")
    parser.add_argument("--run", type=Path, default=ROOT, help="--paired's finished run")
    parser.add_argument("--draws", type=int, default=4, help="--paired's draws")
    parser.add_argument(
        "--realisations", type=int, default=REALISATIONS, help="click realisations per subject"
    )
    cli = parser.parse_args()
    if cli.report:
        report(json.loads(cli.report.read_text()))
        sys.exit(0)
    if cli.paired is not None:
        for name in cli.subjects or ["synth02"]:
            paired(cli.run.resolve(), name, cli.paired, cli.draws)
        sys.exit(0)
    found = {}
    for name in cli.subjects or ["synth01", "synth02", "synth04"]:
        found[name] = measure(name, cli.realisations)
        if cli.out:
            cli.out.write_text(json.dumps(found))
    report(found)
