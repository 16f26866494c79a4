# Ingest: one take's input files -> arrays on the shared pixel grid, with input checksums.
# A stereo take is reconstructed here into the range image of its left camera, an RGB-D take's
# depth resampled onto its colour camera, a mesh take rendered through a virtual camera.


rule check_subject:
    """Check every sheet row and input file of a subject at once (cheap reads): stop the subject on its own or its neutral's problems, name the takes to leave out."""
    input:
        get_subject_files_flat,
    output:
        "results/{subject}/check.json",
    log:
        "logs/check_subject/{subject}.log",
    benchmark:
        "benchmarks/rules/check_subject/{subject}.tsv"
    resources:
        mem_mb=500,
        runtime=1,
    params:
        problems=get_subject_problems,
        rows=get_subject_rows,
        files=get_subject_files,
    script:
        "../scripts/check_subject.py"


rule ingest:
    """Read one take's scan files onto the pixel grid with checksums: a stereo pair reconstructed, RGB-D depth resampled onto the colour image, a mesh rendered."""
    input:
        unpack(get_take_inputs),
        # ancient: a rewritten check.json (another take's file changed) re-ingests no take
        check=ancient("results/{subject}/check.json"),
    output:
        part="results/{subject}/takes/{take}/ingest.h5",
    log:
        "logs/ingest/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/ingest/{subject}/{take}.tsv"
    resources:
        mem_mb=800,
        runtime=2,
    params:
        row=take_row,
        roles=get_take_roles,
        stereo=get_stereo_params,
        mesh_camera=get_mesh_camera_params,
    script:
        "../scripts/ingest.py"
