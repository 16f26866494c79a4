"""The pipeline's stages, each once: the workflow's scripts, the parameter sweeps and the tests
call the same functions.

One module per stage (:mod:`ingest`, :mod:`repair`, :mod:`fit`, :mod:`align`, :mod:`refine`, :mod:`motion`,
:mod:`motion_noise`, :mod:`morph`, :mod:`modal`, :mod:`accuracy`). Each module

- maps its config sections to its typed parameters (``Params.from_config``),
- turns its inputs (arrays read from the parts of the stages before it) into the datasets it
  writes (a :class:`~scan2morph.stages.part.Part`), building store paths only through
  :mod:`scan2morph.store.paths`,
- and, for the stages a sweep can re-run, offers ``apply(data, run)``: the stage over a whole
  subject held in memory (:class:`~scan2morph.stages.part.Run`).

The subject-level stages share one signature, ``run(template, subject, data, params_or_config)``:
``template`` is the base template (``resources/template.npz``), ``subject`` a
:class:`~scan2morph.stages.part.Subject` (its takes by kind and label), ``data`` the datasets of
the parts the stage reads, keyed by store path.

The adapters under ``workflow/scripts`` only read parts, call a stage and write its part.
"""

from scan2morph.stages.part import Part, Run, Subject

__all__ = ["Part", "Run", "Subject"]
