# Synthetic subjects with exact ground truth, written in the formats users bring.
# One job per subject: the procedural head is built once and rendered for every take (a job per
# take would pay ~1 s of imports and ~1.4 s of head building for ~0.35 s of range or ~1 s of
# stereo rendering). A take is a range scan, a stereo pair, an RGB-D take or a mesh scan; subjects
# whose takes have the same modalities share one rule (synth_subject: no stereo takes;
# synth_stereo_subject: with stereo takes; numbered when several groups share a name).


for _group in synth_groups():

    rule:
        """Render every take of one synthetic subject (range scans, stereo pairs, RGB-D takes or mesh scans) with landmark clicks, and its exact ground truth."""
        name:
            _group["name"]
        output:
            xyz=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}.abs.gz", _group["takes"], "range"
            ),
            color=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}.png", _group["takes"], "range"
            ),
            left=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}_left.png",
                _group["takes"],
                "stereo",
            ),
            right=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}_right.png",
                _group["takes"],
                "stereo",
            ),
            calibration=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}_calib.yaml",
                _group["takes"],
                "stereo",
            ),
            depth=synth_depth_files(_group["takes"]),
            rgbd_color=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}.png", _group["takes"], "rgbd"
            ),
            intrinsics=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}_intrinsics.yaml",
                _group["takes"],
                "rgbd",
            ),
            mesh=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/{{take}}.ply", _group["takes"], "mesh"
            ),
            landmarks=synth_landmark_files(_group["takes"]),
            truth=synth_files(
                f"{SYNTH_ROOT}/{{subject}}/truth/{{take}}.npz", _group["takes"]
            ),
        log:
            f"logs/{_group['name']}/{{subject}}.log",
        benchmark:
            f"benchmarks/rules/{_group['name']}/{{subject}}.tsv"
        wildcard_constraints:
            subject="|".join(_group["subjects"]),
        resources:
            mem_mb=1800 if "stereo" in _group["name"] else 1200,
            runtime=7 if "stereo" in _group["name"] else 5,
        params:
            takes=_group["takes"],
            seed=config["synthetic"]["seed"],
            scanner=config["synthetic"]["scanner"],
            rig=config["synthetic"]["stereo"]["rig"],
            rgbd=config["synthetic"]["rgbd"]["sensor"],
            mesh=config["synthetic"]["mesh"]["scanner"],
            code=code_prints(["synth"]),
        script:
            "../scripts/synth_subject.py"
