"""The studies of ``petsc-htp bench``, one module each, and :data:`STUDIES`, their registry.

A study is a module here defining ``STUDY``, an instance of a
:class:`~.base.Study` subclass (what it measures, the solves it expects, its
sizes, report section, charts and README part); adding one means adding its
module's name to :data:`ORDER`, the order of the CLI, the report and README.
"""
from importlib import import_module

ORDER = ("table", "sequence", "defaults", "bare", "foreign", "scale", "curves", "scaling", "stability", "generalization", "size", "rank", "profile", "fastpath",
         "simulation")
STUDIES = {s.name: s for s in (import_module(f"{__name__}.{module}").STUDY for module in ORDER)}


def defaults() -> list:
    """Names of the studies a plain ``petsc-htp bench`` runs."""
    return [name for name, s in STUDIES.items() if s.default]


def sizes() -> list:
    """Every study's size settings, each once, in registry order."""
    return list({size.name: size for s in STUDIES.values() for size in s.sizes}.values())
