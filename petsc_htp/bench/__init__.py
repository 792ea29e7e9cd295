"""``petsc-htp bench``: every method through PETSc on the same frames, one results folder.

``python -m petsc_htp.bench --quick`` runs a CI-sized benchmark; ``-h`` lists
the studies and flags. Each study is one module of :mod:`.studies` (what it
measures, its sizes, report section, charts and README part), registered in
``studies.ORDER``; they share :mod:`.aggregate` (grouping and summarising
rows), :mod:`.markdown` and :mod:`.plotting`. The rest: :mod:`.cli` (flags and
orchestration), :mod:`.meta` (meta.json), :mod:`.methods` (which options
files), :mod:`.runner` (one solve through PETSc or pyamg), :mod:`.cases`
(problems from held-out frames), :mod:`.training` (the models studies train),
:mod:`.spectrum`, :mod:`.report`, :mod:`.readme`, :mod:`.modelcard` and
:mod:`.store` (atomic result files).
"""


def main(argv=None) -> int:
    """Run ``petsc-htp bench`` with ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    from .cli import main as run

    return run(argv)
