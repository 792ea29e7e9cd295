"""HTPPC where ranks own no rows: PCTELESCOPE moves the rows to a subcommunicator and HTPPC runs there.

The two-level method needs rows on every rank of its communicator. Above :data:`.sizing.REDUNDANT_MAX` rows, where
some ranks own none, :class:`.direct.DirectPC` of kind 'telescope' is PETSc's PCTELESCOPE under HTPPC's own prefix
(``<prefix>htp_``: ``-htp_leaf_*`` stays the leaves'), its reduction factor the ranks over those that own rows,
rounded up (4 ranks of which 3 own rows: 2), and inside it, on its PREONLY KSP, HTPPC again, whose options are
``-htp_telescope_htp_*``. An error of that inner HTPPC's setup reaches only the ranks of the subcommunicator:
:func:`set_up_everywhere` raises it on every rank.
"""
from __future__ import annotations

from ..collective import Collective
from .inner import set_up

OPTIONS = {"pc_type": "telescope", "telescope_pc_type": "python", "telescope_pc_python_type": "petsc_htp.HTPPC"}


def options(mat, rows) -> dict:
    """The telescope's PETSc options for ``mat`` (this rank's ``rows``): :data:`OPTIONS` and the reduction factor
    (collective)."""
    owning = Collective(mat.getComm()).sum(int(rows.shape[0] > 0))
    factor = -(-mat.getComm().getSize() // max(owning, 1))
    return {**OPTIONS, "pc_telescope_reduction_factor": str(factor)}


def named(exc) -> str:
    """The message of the deepest ValueError in ``exc``'s chain of causes (HTPPC's named errors), else ``exc``'s."""
    found, seen = None, exc
    while seen is not None:
        if isinstance(seen, ValueError):
            found = seen
        seen = seen.__cause__ or (None if seen.__suppress_context__ else seen.__context__)
    return str(found if found is not None else exc).strip()


def set_up_everywhere(pc, prefix, rest):
    """:func:`.inner.set_up` of the telescope ``pc`` (on several ranks: some own no rows) and one application
    (PCTELESCOPE sets its KSP up at the first); where that raised on some ranks, the error on every rank (the others
    raise a ValueError with its message; collective)."""
    coll, failure = Collective(pc.getComm()), None
    x, y = pc.getOperators()[0].createVecs()
    try:
        set_up(pc, prefix, rest)
        x.set(0.0)
        pc.apply(x, y)
    except Exception as exc:                               # the subcommunicator's ranks only
        failure = exc
    finally:
        x.destroy()
        y.destroy()
    messages = [m for m in coll.mpi.allgather(None if failure is None else named(failure)) if m]
    if failure is not None:
        raise failure
    if messages:
        raise ValueError(messages[0])
