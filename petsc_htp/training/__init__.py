"""What training needs besides the networks: losses (:mod:`.loss`), checkpoint files (:mod:`.checkpoint`) and a
plain NumPy PCG for training-time evaluation (:mod:`.pcg`). None of it is loaded by HTPPC's default."""
