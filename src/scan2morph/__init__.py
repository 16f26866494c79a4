"""scan2morph: 3D face scans to subject-specific morphable face models.

The library is split by concept and data flows one way::

    io -> scan -> template -> landmarks -> align -> refine -> motion -> morph / modal
       -> render / report -> stages

Nothing here imports snakemake; the workflow under ``workflow/`` is a thin layer on top.
"""

from scan2morph.version import __version__

__all__ = ["__version__", "load_model"]


def __getattr__(name: str):
    # scan2morph.load_model without importing h5py and the stages for every `import scan2morph`
    if name == "load_model":
        from scan2morph.model import load_model

        return load_model
    raise AttributeError(f"module 'scan2morph' has no attribute {name!r}")
