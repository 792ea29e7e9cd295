"""A two-phase flow that solves a pressure-Poisson system every frame: the scene (:mod:`.flow`), the persistent
PETSc solver and reuse policy (:mod:`.simulation`) and its charts and animation (:mod:`.plot`)."""
