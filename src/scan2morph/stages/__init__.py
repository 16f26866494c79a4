"""The pipeline's stages, each once: the workflow's scripts, the parameter sweeps and the tests
call the same functions.

One module per stage (:mod:`check`, :mod:`ingest`, :mod:`repair`, :mod:`fit`, :mod:`align`,
:mod:`refine`, :mod:`consensus`, :mod:`motion`, :mod:`motion_noise`, :mod:`morph`, :mod:`modal`, :mod:`store`,
:mod:`accuracy`, :mod:`report`, :mod:`synth`). Every stage module has

- a frozen ``Params`` dataclass with ``Params.from_config(config: Mapping) -> Params``, taking the
  whole validated config (one shape everywhere: a stage picks its own sections); a stage without
  parameters has an empty ``Params``;
- one ``run`` of the shape of its level, returning a :class:`~scan2morph.stages.part.Part`
  (the datasets and attributes it writes, built with store paths from
  :mod:`scan2morph.store.paths`; products for the writer - tables, meshes - in ``Part.files``):

  - per-take stages: ``run(template, take: Take, params: Params) -> Part``, with ``take`` a
    :class:`~scan2morph.stages.part.Take` (the take's ids, kind, label, neutral, and the datasets,
    attributes, files and sheet row it reads);
  - per-subject stages: ``run(template, subject: Subject, data: Mapping, params: Params) -> Part``,
    with ``subject`` a :class:`~scan2morph.stages.part.Subject` (its takes by kind and label) and
    ``data`` the datasets of the parts the stage reads, keyed by store path;

  ``template`` is the base template (``resources/template.npz``); a stage that does not need it
  still takes it, for one shape (ingest and check may be given ``None``);
- and, for the stages a sweep can re-run, ``apply(data, run_)``: the stage over a whole subject
  held in memory (:class:`~scan2morph.stages.part.Run`), returning its datasets.

The adapters under ``workflow/scripts`` only read parts, call a stage and write its part.
"""

from scan2morph.stages.part import Part, Run, Subject, Take

__all__ = ["Part", "Run", "Subject", "Take"]
