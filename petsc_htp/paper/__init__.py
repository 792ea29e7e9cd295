"""The paper's variant: a transformer emits the factors of an H-matrix preconditioner (the reference row).

:mod:`.partition` (leaves and tiles) → :mod:`.features` → :mod:`.model` (the network) → :mod:`.apply`
(the H-matrix apply) → :mod:`.inference` (analysis and numeric steps, :class:`~.inference.HTP`);
training: :mod:`.train`, :mod:`.fit` (with :mod:`petsc_htp.training.loss`), :mod:`.weights` (its checkpoints).
"""
