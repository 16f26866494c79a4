"""Saving and loading the template definition (``resources/template.npz``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.jobs import write_npz
from scan2morph.template.mesh import TEMPLATE_FORMAT, Template


def save_template(path: str | Path, template: Template) -> None:
    """Write a template as ``.npz`` (arrays + JSON for the dicts): the same template gives the
    same bytes (:func:`scan2morph.jobs.write_npz`), so that building it again re-runs no take."""
    fid = {k: [v[0].tolist(), v[1].tolist()] for k, v in template.fiducials.items()}
    arrays = {
        "format": np.int64(TEMPLATE_FORMAT),
        "vertices": template.vertices,
        "faces": template.faces,
        "ibug_xy": template.ibug_xy,
        "ibug_vertex": template.ibug_vertex,
        "boundary": template.boundary,
        "mouth_boundary": template.mouth_boundary,
        "level": np.int64(template.level),
        "fiducials": json.dumps(fid),
        "named": json.dumps(template.named),
    }
    write_npz(Path(path), arrays)


def load_template(path: str | Path) -> Template:
    """Read a template written by :func:`save_template`."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "template file not found")
    try:
        with np.load(path, allow_pickle=False) as d:
            if int(d["format"]) != TEMPLATE_FORMAT:
                raise InputError(
                    path, f"template format {int(d['format'])}, expected {TEMPLATE_FORMAT}"
                )
            fid = {
                k: (np.array(a), np.array(b))
                for k, (a, b) in json.loads(str(d["fiducials"])).items()
            }
            return Template(
                vertices=d["vertices"],
                faces=d["faces"],
                ibug_xy=d["ibug_xy"],
                ibug_vertex=d["ibug_vertex"],
                fiducials=fid,
                named=json.loads(str(d["named"])),
                boundary=d["boundary"],
                mouth_boundary=d["mouth_boundary"],
                level=int(d["level"]),
            )
    except KeyError as exc:
        raise InputError(path, f"template key {exc} missing") from None
