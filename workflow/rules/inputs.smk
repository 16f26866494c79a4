# Input and params functions of the stage rules (ingest to accuracy): each takes the job's
# wildcards and looks the subject or take up in the take table of common.smk.
import functools
from pathlib import Path

from scan2morph.io.mesh_file import companion_files
from scan2morph.sheet import (
    MULTI_PATH_COLUMNS,
    SYNTHETIC_LANDMARKS,
    input_roles,
    rgbd_frames,
    split_paths,
    synthetic_depth_frames,
)
from scan2morph.stages import stage_job


# --- one take ---
def take_row(wildcards):
    """The sheet row of a take, as a plain dict (tracked as a param)."""
    row = TAKES.loc[(wildcards.subject, wildcards.take)]
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}


def get_take_inputs(wildcards):
    """The input files of a take that exist or will be generated (a missing one is reported
    by the subject's check job, so that the DAG still builds and other subjects run)."""
    return take_inputs(wildcards.subject, wildcards.take)


def take_inputs(subject, take):
    row = TAKES.loc[(subject, take)]
    files = {}
    for role in input_roles(row):
        if role in MULTI_PATH_COLUMNS:  # several files (or a folder): a list
            parts = split_paths(row[role])
            if parts and (row["synthetic"] or all(Path(p).exists() for p in parts)):
                files[role] = parts if row["synthetic"] else frame_files(parts)
            continue
        path = row[role]
        if path and (row["synthetic"] or Path(path).is_file()):
            files[role] = path
    return files


def frame_files(parts):
    """The files a user's depth cell names, a folder's frames listed: each is tracked (a frame
    replaced inside the folder re-runs its take) and checksummed. As named when they name no
    frame (the subject's check job says why). Imported here: it imports OpenCV."""
    from scan2morph.io.depth_image import depth_frame_paths

    try:
        return [str(p) for p in depth_frame_paths(parts)]
    except InputError:
        return parts


# how much of each mesh file a Snakemake start reads for its MTL (a scan may be hundreds of MB)
COMPANION_SCAN_BYTES = 1 << 20


@functools.cache
def companions(subject, take):
    """The files a user's mesh file names (an OBJ's MTL and texture, a glTF's buffers and
    images: ``scan2morph.io.mesh_file.companion_files``), as the take input ``companions``
    (none for other takes): a texture changed beside its mesh re-runs the take. Found once a
    Snakemake (the job's inputs and stamps both ask); its callers do not change it."""
    if TAKES.loc[(subject, take), "synthetic"]:
        return {}
    mesh = take_inputs(subject, take).get("mesh")
    found = companion_files(mesh, max_bytes=COMPANION_SCAN_BYTES) if mesh else []
    return {"companions": [str(f) for f in found]} if found else {}


def get_take_stamps(wildcards):
    """Size (bytes) and modification time (ns) of each of a user take's input files (with its
    mesh's :func:`companions`), by sheet column. Snakemake re-runs a take whose file is newer
    than its results; as a param, a file replaced by one with an older time (``rsync -a``,
    ``cp -p``, an archive unpacked) re-runs it too, and its stages, fingerprinted by the files'
    checksums, compute what the new content changes. A synthetic take's files are the
    workflow's own outputs: none."""
    subject, take = wildcards.subject, wildcards.take
    if TAKES.loc[(subject, take), "synthetic"]:
        return {}
    files = take_inputs(subject, take) | companions(subject, take)
    stats = {
        role: [os.stat(f) for f in ([value] if isinstance(value, str) else value)]
        for role, value in files.items()
    }
    return {
        role: [[st.st_size, st.st_mtime_ns] for st in sts]
        for role, sts in stats.items()
    }


def get_stereo_params(wildcards):
    """Stereo reconstruction parameters of a stereo take; {} for other takes, so that changing
    them reruns only stereo takes."""
    modality = TAKES.loc[(wildcards.subject, wildcards.take), "modality"]
    return dict(config["stereo"]) if modality == "stereo" else {}


def get_mesh_camera_params(wildcards):
    """The virtual camera of a mesh take; {} for other takes (changing it reruns mesh takes only)."""
    modality = TAKES.loc[(wildcards.subject, wildcards.take), "modality"]
    return dict(config["mesh_camera"]) if modality == "mesh" else {}


def get_take_roles(wildcards):
    """The sheet columns that name the take's input files (its modality's, and an optional
    texture when given; none for an unknown modality, which the subject's check job reports).
    """
    return input_roles(TAKES.loc[(wildcards.subject, wildcards.take)])


def synth_depth_files(takes):
    """The depth frames a synthetic subject's generator writes for its RGB-D takes, in take
    order (``synthetic.rgbd.sensor.frames`` per take), with ``{subject}`` kept."""
    frames = rgbd_frames(config["synthetic"]["rgbd"])
    stem = f"{SYNTH_ROOT}/{{subject}}/{{take}}"
    return [
        f
        for t in takes
        if t["modality"] == "rgbd"
        for f in synthetic_depth_frames(stem.replace("{take}", t["take"]), frames)
    ]


def synth_landmark_files(takes):
    """The landmark files a synthetic subject's generator writes (3D points for mesh takes,
    iBUG .pts otherwise), with ``{subject}`` kept."""
    stem = f"{SYNTH_ROOT}/{{subject}}/{{take}}"
    return [
        SYNTHETIC_LANDMARKS.get(t["modality"], "{stem}.pts").format(
            stem=stem.replace("{take}", t["take"])
        )
        for t in takes
    ]


def get_take_ids(wildcards):
    """kind, label and the subject's neutral take of a take (a per-take stage's Take)."""
    row = TAKES.loc[(wildcards.subject, wildcards.take)]
    return {
        "kind": row["kind"],
        "label": row["label"],
        "neutral": get_neutral_take(wildcards),
    }


# --- the takes of a subject ---
def get_subject_problems(wildcards):
    """The sheet's problems of the subject, as (take, problem); take empty for the subject's own."""
    return PROBLEMS.get(wildcards.subject, [])


def get_take_problems(wildcards):
    """The sheet's problems of one take (its job's verdict when there are any)."""
    return [p for t, p in PROBLEMS.get(wildcards.subject, []) if t == wildcards.take]


def get_subject_rows(wildcards):
    """subject, take, kind, label, modality and units of each of the subject's rows (its check
    job's params: the units scale a mesh before its size is checked)."""
    rows = TAKES.loc[wildcards.subject]
    return rows[["subject", "take", "kind", "label", "modality", "units"]].to_dict(
        "records"
    )


def get_subject_files(wildcards):
    """take -> {sheet column: path} of the subject's input files that exist or will be generated."""
    return {
        take: take_inputs(wildcards.subject, take)
        for take in takes_of(wildcards.subject)
    }


def get_check_inputs(wildcards):
    """The subject check job's input files: its neutral's as they are (a neutral whose file
    changes is checked again, and a problem stops the subject before its takes run), the other
    takes' ``ancient`` (their job checks a changed file itself: check.take_verdict)."""
    neutral = get_neutral_take(wildcards)
    out = set()
    for take, files in get_subject_files(wildcards).items():
        for value in files.values():
            for f in [value] if isinstance(value, str) else value:
                out.add(f if take == neutral else ancient(f))
    return sorted(out)


def get_neutral_take(wildcards):
    neutral = takes_of_kind(wildcards.subject, "neutral")
    return neutral[0] if neutral else ""


def get_viseme_takes(wildcards):
    return takes_of_kind(wildcards.subject, "viseme")


def get_take_kinds(wildcards):
    """Kind of every take of the subject (take -> kind), in sheet order."""
    rows = TAKES.loc[wildcards.subject]
    return dict(zip(rows["take"], rows["kind"]))


def get_take_labels(wildcards):
    rows = TAKES.loc[wildcards.subject]
    return dict(zip(rows["take"], rows["label"]))


# --- the per-take parts a subject-level stage reads ---
def get_take_parts(stage):
    """An input function: the ``stage`` part of every take of the subject."""

    def parts(wildcards):
        return _take_files(
            f"results/{{subject}}/takes/{{take}}/{stage}.h5",
            wildcards.subject,
            takes_of(wildcards.subject),
        )

    return parts


def get_noise_repairs(wildcards):
    """The repair and landmarks parts of the neutral and the visemes (the click-noise refits'
    data)."""
    takes = takes_of_kind(wildcards.subject, "neutral") + get_viseme_takes(wildcards)
    return sum(
        (
            _take_files(
                f"results/{{subject}}/takes/{{take}}/{stage}.h5",
                wildcards.subject,
                takes,
            )
            for stage in ("repair", "landmarks")
        ),
        [],
    )


def get_neutral_repair(wildcards):
    take = get_neutral_take(wildcards)
    return f"results/{wildcards.subject}/takes/{take}/repair.h5" if take else []


def get_neutral_fit(wildcards):
    take = get_neutral_take(wildcards)
    return f"results/{wildcards.subject}/takes/{take}/fit.h5" if take else []


def get_viseme_aligns(wildcards):
    return _take_files(
        "results/{subject}/takes/{take}/align.h5",
        wildcards.subject,
        get_viseme_takes(wildcards),
    )


def get_viseme_refines(wildcards):
    """The visemes' refine parts (motion_noise reads their attributes: which were refined by
    the surface's shape)."""
    return _take_files(
        "results/{subject}/takes/{take}/refine.h5",
        wildcards.subject,
        get_viseme_takes(wildcards),
    )


def get_subject_take_parts(wildcards):
    """Every take part the subject's job reads (the store merges them all)."""
    takes = takes_of(wildcards.subject)
    return sum(
        (
            _take_files(
                f"results/{{subject}}/takes/{{take}}/{stage}.h5",
                wildcards.subject,
                takes,
            )
            for stage in ("repair", "landmarks", "fit", "align", "refine")[
                : 5 if REFINE else 4
            ]
        ),
        [],
    )


def get_subject_take_records(wildcards):
    """The take jobs' records of their parts' fingerprints (``stages.json``)."""
    return _take_files(
        "results/{subject}/takes/{take}/stages.json",
        wildcards.subject,
        takes_of(wildcards.subject),
    )


def get_subject_take_jobs(wildcards):
    """The take jobs' records of their last finished runs (``job.json``)."""
    return _take_files(
        "results/{subject}/takes/{take}/job.json",
        wildcards.subject,
        takes_of(wildcards.subject),
    )


def get_subject_stage_reads(wildcards):
    """The take parts each stage of the subject's job reads (stage -> paths), in the order the
    stage reads them."""
    neutral = [get_neutral_fit(wildcards), get_neutral_repair(wildcards)]
    return {
        "consensus": (
            sum(
                (
                    get_take_parts(stage)(wildcards)
                    for stage in ("repair", "landmarks", "fit", "align", "refine")
                ),
                [],
            )
            if REFINE
            else []
        ),
        "motion": get_take_parts("fit")(wildcards)
        + get_take_parts("align")(wildcards)
        + (get_take_parts("refine")(wildcards) if REFINE else []),
        "motion_noise": get_noise_repairs(wildcards)
        + get_viseme_aligns(wildcards)
        + (get_viseme_refines(wildcards) if REFINE else []),
        "morph": [f for f in neutral if f],
        "modal": [f for f in neutral if f],  # the expression meshes' texture
        "store": get_subject_take_parts(wildcards),
    }


def get_truth_files(wildcards):
    return expand(
        f"{SYNTH_ROOT}/{{subject}}/truth/{{take}}.npz",
        subject=wildcards.subject,
        take=takes_of(wildcards.subject),
    )


# --- the take job ---
def get_take_job_inputs(wildcards):
    """A take job's input files (:func:`take_inputs`, a mesh's :func:`companions`) and, for a
    take other than the neutral, the neutral's parts its stages read (``neutral_repair``,
    ``neutral_landmarks``, ``neutral_fit``), their fingerprints (``neutral_stages``) and the
    record of the neutral's finished job (``neutral_job``)."""
    files = take_inputs(wildcards.subject, wildcards.take)
    files |= companions(wildcards.subject, wildcards.take)
    neutral = get_neutral_take(wildcards)
    if not neutral or wildcards.take == neutral:
        return files
    folder = f"results/{wildcards.subject}/takes/{neutral}"
    parts = {f"neutral_{s}": f"{folder}/{s}.h5" for s in ("repair", "landmarks", "fit")}
    # the neutral's fingerprints and the record of its finished job (a failed one runs again)
    records = {
        "neutral_stages": f"{folder}/stages.json",
        "neutral_job": f"{folder}/job.json",
    }
    return files | parts | records


def stage_files(pattern, stages):
    """A params function: ``pattern`` (with ``{stage}``, ``{subject}`` and ``{take}`` where a
    job has one) for each of ``stages``, stage -> path (the stages' logs and benchmark files).
    """

    def files(wildcards):
        return {s: pattern.format(stage=s, **dict(wildcards.items())) for s in stages}

    return files


@functools.cache
def _code_fingerprints():
    """Every stage's code fingerprint, computed once a run (the library's modules parsed in
    this process, not in each job: about 1 CPU-s, 0.08 with the parses kept on disk)."""
    return stage_job.code_fingerprints(
        [*stage_job.TAKE_STAGES, *stage_job.SUBJECT_STAGES, *stage_job.JOB_CODE]
    )


def code_prints(stages):
    """A params function: the code fingerprint of each of ``stages``, stage -> hex
    (:func:`scan2morph.stages.stage_job.code_fingerprints`). A job's stages take it into their
    fingerprints, and as a param it makes Snakemake run the job again when the code one of its
    stages runs has changed."""

    def prints(wildcards):
        return {s: _code_fingerprints()[s] for s in stages}

    return prints
