"""What training needs besides the networks: losses (:mod:`.loss`), checkpoint files (:mod:`.checkpoint`) and a
plain NumPy PCG for training-time evaluation (:mod:`.pcg`). HTPPC's default loads only :mod:`.checkpoint`
(its option checks, no torch)."""
