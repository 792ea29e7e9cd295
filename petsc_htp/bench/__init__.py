"""``petsc-htp bench``: every method through PETSc on the same frames, one results folder.

``python -m petsc_htp.bench --quick`` runs a CI-sized benchmark; ``-h`` lists
the studies and flags. The modules: :mod:`.cli` (flags and orchestration),
:mod:`.methods` (which options files), :mod:`.runner` (one solve through PETSc
or pyamg), :mod:`.cases` (frames and stress cases), :mod:`.studies` (what each
study measures), :mod:`.training` (the models studies train), :mod:`.spectrum`,
:mod:`.stats`, :mod:`.tables`, :mod:`.report`, :mod:`.charts`, :mod:`.readme`
and :mod:`.store` (atomic result files).
"""


def main(argv=None) -> int:
    """Run ``petsc-htp bench`` with ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    from .cli import main as run

    return run(argv)
