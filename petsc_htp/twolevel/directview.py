"""``-ksp_view``'s lines for one factor of the whole matrix (:class:`.direct.DirectPC`): what runs, on how many
rows and why, where its options go, its setup times and memory. It names the PC that runs, which options under the
prefix may have made other than the one chosen (``-htp_leaf_pc_type icc`` on a matrix chosen for the band,
``-htp_leaf_redundant_pc_type`` on several ranks)."""
from __future__ import annotations

from petsc4py import PETSc

from .inner import held

BLOCKED_TEXT = {"bjacobi": "ICC(0) of each rank's diagonal block (PCBJACOBI)",
                "asm": "ICC(0) of each rank's block grown by {overlap} layers (PCASM, basic)"}
CHOSEN_TEXT = {"cholesky": "one sparse Cholesky factor (exact: the solve starts on x0 = M r0)",
               "band": "one banded Cholesky factor (exact: the solve starts on x0 = M r0)",
               "icc": "ICC(0), whose iterations cost less here than an exact factor or the two-level method"}
CHOSEN_TYPE = {"cholesky": "cholesky", "band": "python", "icc": "icc"}   # the PC type each choice makes
GATHERED_TYPE = {"cholesky": "lu"}                     # several ranks: the gathered factor's PC and words
GATHERED_TEXT = {"cholesky": "one sparse LU factor (exact: the solve starts on x0 = M r0)"}


def factor_bytes(d, blocked, own) -> int:
    """Bytes of the factor of the :class:`.direct.DirectPC` ``d`` (``blocked``: its kinds of one ICC(0) per rank;
    ``own``: its kinds that gather nothing; a banded factor's band by :func:`.inner.held`). On several ranks the
    whole matrix's values, which every rank gathers and factors (PCREDUNDANT does not show its factor)."""
    kind = d.pc.getType()                        # options under the prefix may have made another PC
    if kind == "telescope":
        return 0                                 # the telescoped HTPPC's view shows its own
    if kind in blocked:
        sub = d.pc.getBJacobiSubKSP() if kind == "bjacobi" else d.pc.getASMSubKSP()
        return 8 * held(sub[0].getPC())
    if d.ranks > 1 and d.kind not in own:
        return d.gathered
    return 8 * held(d.pc)


def describe(d, overlap) -> list:
    """The lines of the :class:`.direct.DirectPC` ``d`` (``overlap``: the layers PCASM's blocks grow by)."""
    n = d.mat.getSize()[0]
    what = CHOSEN_TEXT.get(d.kind, "")
    if d.kind == "telescope":
        what = "HTPPC on the ranks the rows are moved to (PCTELESCOPE)"
        where = f" (options -{d.prefix}telescope_htp_*; its view below)"
        memory = "memory: the telescoped HTPPC's, below"
    elif d.kind in BLOCKED_TEXT:
        what = BLOCKED_TEXT[d.kind].format(overlap=overlap)
        where = f" (options -{d.prefix}sub_*)"
        memory = f"memory on this rank: {d.nbytes / max(d.mat.getLocalSize()[0], 1):.0f} bytes per unknown"
    elif d.ranks > 1 and d.kind != "band":
        chosen = GATHERED_TYPE.get(d.kind, CHOSEN_TYPE[d.kind])
        what = GATHERED_TEXT.get(d.kind, what)
        asked = PETSc.Options(d.prefix).getString("redundant_pc_type", chosen)
        factor = f"{chosen}, {d.ordering} ordering"
        if asked != chosen:                           # (PCREDUNDANT's inner PC has no getter in petsc4py)
            what = f"PETSc's {asked}, as -{d.prefix}redundant_pc_type asks (chosen: {what})"
            factor = asked
        where = (f", gathered and factored on each of the {d.ranks} ranks (PCREDUNDANT: "
                 f"{factor}; options -{d.prefix}redundant_*)")
        memory = f"memory: {d.nbytes / n:.0f} bytes per unknown of values on every rank, and their factor"
    else:
        band, kind = d._band(), d.pc.getType()
        if kind != CHOSEN_TYPE[d.kind]:                         # an option under the prefix made another PC
            what = f"PETSc's {kind} of the whole matrix, as -{d.prefix}pc_type asks (chosen: {CHOSEN_TEXT[d.kind]})"
        ordering = f", {d.ordering} ordering" if d.ordering else ""
        what_factor = band.describe() if band is not None else f"{d.pc.getFactorSolverType()} {kind}{ordering}"
        where = f" ({what_factor}; options -{d.prefix}*)"
        memory = f"memory: {d.nbytes / max(n, 1):.0f} bytes per unknown"
    return [f"whole matrix: {what}; {n} rows, {d.why or 'within the sizes where it is cheapest'}{where}"
            + (f"; {d.null_components} null component(s) grounded" if d.null_components else ""),
            f"setup ms: analysis {d.analysis_ms:.1f}; factor {d.times.get('factor', 0.0):.1f}", memory]
