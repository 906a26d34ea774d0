"""The strain-limiting families' names, ids and constraint counts (docs/method.md §3), with
no Taichi types: importable before ``backend.init`` (the benchmarks list the methods before
they choose the precision; ``constraints.py`` builds its structs at import, in whatever float
type Taichi has then)."""
METHODS = ("svd", "warp-weft", "mapping")
# The strain settings' choices: the three families, or no strain limiting.
STRAIN_METHODS = METHODS + ("none",)
N_CONSTRAINTS = {"svd": 4, "warp-weft": 6, "mapping": 8}
METHOD_IDS = {"svd": 0, "warp-weft": 1, "mapping": 2}
# The ids by name: the kernels take the method's id at run time (strain/al.py ``assemble_face``).
SVD, WARP_WEFT, MAPPING = (METHOD_IDS[name] for name in METHODS)
K_MAX = 8

# The solver orders the mapping family's principal pairs by magnitude (pair A = eta1), not by
# alignment with the warp. Ordered by alignment, the pairs swap where the principal axes cross
# 45 degrees from the grain, and there each constraint's value jumps from c (eta1 - 1) to
# c (eta2 - 1): the AL merit is discontinuous, and Newton's model fails across it. Ordered by
# magnitude they swap only at eta1 = eta2, where the isotropy closure (constraints.MAPPING_ISO) makes both pairs' values
# equal, so every constraint is continuous (its multiplier changes meaning there, a warm-start
# matter only).
MAPPING_PAIRS_BY_ALIGNMENT = False
