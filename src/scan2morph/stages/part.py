"""What every stage hands on: the datasets it writes, and the subject it runs for."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from scan2morph.errors import InputError
from scan2morph.store import paths

if TYPE_CHECKING:  # a type only: the template (and scipy) stay unimported until used
    from scan2morph.template import Template


@dataclass
class Part:
    """A stage's result.

    Attributes
    ----------
    datasets : dict store path -> array
        What the stage writes into its part file (paths from :mod:`scan2morph.store.paths`).
    attrs : dict group path -> dict
        HDF5 attributes per group (``"/"`` is the root).
    files : dict
        Products written beside the part (tables, meshes): name -> object, for the stage's own
        writer.
    """

    datasets: dict[str, object] = field(default_factory=dict)
    attrs: dict[str, dict] = field(default_factory=dict)
    files: dict[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class Subject:
    """A subject's takes, in sheet order.

    Attributes
    ----------
    name : str
        Subject id (for messages).
    kinds : mapping take -> ``neutral`` | ``viseme`` | ``expression``
    labels : mapping take -> label (``car``, ``smile``, ...)
    """

    name: str
    kinds: Mapping[str, str]
    labels: Mapping[str, str]

    @property
    def neutral(self) -> str:
        """The one neutral take."""
        neutral = [t for t, k in self.kinds.items() if k == "neutral"]
        if len(neutral) != 1:
            raise InputError(self.name, f"takes: expected exactly one neutral take, got {neutral}")
        return neutral[0]

    @property
    def visemes(self) -> list[str]:
        return [t for t, k in self.kinds.items() if k == "viseme"]

    @property
    def expressions(self) -> list[str]:
        return [t for t, k in self.kinds.items() if k == "expression"]

    def keep(self, takes) -> Subject:
        """The same subject with only the neutral and ``takes`` (e.g. those a stage used)."""
        keep = set(takes) | {self.neutral}
        return Subject(
            self.name,
            {t: k for t, k in self.kinds.items() if t in keep},
            {t: lab for t, lab in self.labels.items() if t in keep},
        )

    def source(self, take: str | None = None) -> str:
        """``subject`` or ``subject/take``, for messages."""
        return self.name if take is None else f"{self.name}/{take}"


@dataclass(frozen=True)
class Take:
    """One take and what a per-take stage reads for it.

    Attributes
    ----------
    subject : str
        Subject id.
    take : str
        Take id.
    kind : str
        ``neutral``, ``viseme`` or ``expression``.
    label : str
        The take's label (``car``, ``smile``, ...).
    neutral : str
        The subject's neutral take id (the take itself for the neutral; ``""`` where the stage
        does not need it: ingest, check, synth).
    data : mapping store path -> array
        The datasets of the parts the stage reads.
    attrs : mapping
        The group attributes the stage reads (e.g. the take group's, with its modality).
    files : mapping role -> path
        The take's input files by sheet role (``xyz``, ``color``, ``left``, ...), for ingest.
    row : mapping
        The take's sheet row.
    """

    subject: str
    take: str
    kind: str
    label: str
    neutral: str = ""
    data: Mapping[str, np.ndarray] = field(default_factory=dict)
    attrs: Mapping = field(default_factory=dict)
    files: Mapping[str, str] = field(default_factory=dict)
    row: Mapping = field(default_factory=dict)

    @classmethod
    def of(cls, subject: Subject, take: str, **inputs) -> Take:
        """``take`` of ``subject``, with ``inputs`` (``data``, ``attrs``, ``files``, ``row``)."""
        if take not in subject.kinds:
            raise InputError(subject.name, f"take {take}: not one of the subject's takes")
        kind, label = subject.kinds[take], subject.labels[take]
        return cls(subject.name, take, kind, label, subject.neutral, **inputs)

    @classmethod
    def from_row(cls, row: Mapping, neutral: str = "", **inputs) -> Take:
        """The take of a sheet row (``subject``, ``take``, ``kind``, ``label``), with ``inputs``
        (``data``, ``attrs``, ``files``)."""
        ids = (str(row[k]) for k in ("subject", "take", "kind", "label"))
        return cls(*ids, neutral, row=row, **inputs)

    @property
    def source(self) -> str:
        """``subject/take``, for messages."""
        return f"{self.subject}/{self.take}"

    @property
    def modality(self) -> str:
        """The take's modality (``range``, ``stereo``, ``mesh``, ``rgbd``): the take group's
        attribute, else its ``camera/modality`` dataset (ingest writes it), else ``range``."""
        if "modality" in self.attrs:
            return str(self.attrs["modality"])
        value = self.data.get(paths.camera(self.take, "modality"), "range")
        return value.decode() if isinstance(value, bytes) else str(value)


@dataclass(frozen=True)
class Run:
    """A whole subject run in memory (the parameter sweeps).

    Attributes
    ----------
    subject : Subject
    template : Template
        The base template (``resources/template.npz``).
    config : mapping section -> mapping
        The config, or at least the sections the stages read (``repair``, ``template``,
        ``align``, ``refine``, ``mask``, ``smoothing``, ``quality``, ``motion_noise``), with any
        swept values set: each stage's ``Params.from_config`` reads it.
    """

    subject: Subject
    template: Template
    config: Mapping[str, Mapping]


def need(data: Mapping[str, np.ndarray], key: str, source: str) -> np.ndarray:
    """``data[key]``, or a clear error naming the dataset and where it was expected from."""
    if key not in data:
        raise InputError(source, f"{key}: missing (expected from the parts of earlier stages)")
    return data[key]
