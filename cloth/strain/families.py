"""The strain-limiting families' names, ids and constraint counts (METHOD.md section 3), with
no Taichi types: importable before ``backend.init`` (the benchmarks list the methods before
they choose the precision; ``constraints.py`` builds its structs at import, in whatever float
type Taichi has then)."""
METHODS = ("svd", "warp-weft", "mapping")
N_CONSTRAINTS = {"svd": 4, "warp-weft": 6, "mapping": 8}
METHOD_IDS = {"svd": 0, "warp-weft": 1, "mapping": 2}
K_MAX = 8
