# Sourced from the repository root by the A/B scripts in results/*/ (P: the Python to run): a byte-compiled worktree
# of each commit in COMMITS under TREES, HTPPC's options in HTP; trees_remove takes the worktrees away.
TREES=$(mktemp -d)
for c in $COMMITS; do
  git worktree add -q "$TREES/$c" $c && (cd "$TREES/$c" && $P -m compileall -q petsc_htp > /dev/null)
done
HTP="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
trees_remove() {
  for c in $COMMITS; do git worktree remove --force "$TREES/$c"; done
  rm -rf "$TREES"
}
