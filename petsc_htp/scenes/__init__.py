"""Problems to solve: the paper's multiphase scene generator (:mod:`.generator`), its cached train and test
sets (:mod:`.dataset`), pictures (:mod:`.plot`) and plain matrices a user would hand over (:mod:`.gallery`).

``make_frame``, ``Frame`` and ``load_dataset`` are importable from here.
"""

_EXPORTS = {"make_frame": "generator", "Frame": "generator", "load_dataset": "dataset"}


def __getattr__(name):
    if name in _EXPORTS:
        from importlib import import_module

        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
