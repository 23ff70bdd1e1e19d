"""The report's variant list: names and what each surrogate adds."""

from __future__ import annotations

from diathermy.report.variants import default_variants
from diathermy.scene import builtin_scene


def test_surrogates_add_their_guarded_and_enriched_variants() -> None:
    names = {v.name: v for v in default_variants({"cnn-w8": "m.pt", "pgd-30": "p.npz"})}
    assert {"cnn-w8", "cnn-w8+patch", "cnn-w8+patch+guard1e-2", "cnn-w8+patch+guard1e-4"} <= set(
        names
    )
    assert names["cnn-w8"].correction == "none" and names["cnn-w8"].guard_tolerance is None
    assert names["cnn-w8+patch"].correction == "patch"
    assert names["cnn-w8+patch+guard1e-4"].guard_tolerance == 1e-4
    applied = names["cnn-w8+patch+guard1e-2"].apply(builtin_scene("fixed-electrode"), 5)
    assert applied.mechanics.correction == "patch" and applied.mechanics.guard_tolerance == 1e-2
    assert names["cnn-w8"].apply(builtin_scene("fixed-electrode"), 5).mechanics.correction == "none"
    assert names["pgd-30"].guard_tolerance is None
    assert names["pgd-30+enrich1e-1"].backend == "pgd"
    assert names["pgd-30+enrich1e-1"].guard_tolerance == 0.1
    assert all(v.backend == "fem" for v in default_variants() if v.name.startswith("fem"))


def test_persistence_stands_beside_the_network_in_the_same_table() -> None:
    """'previous' and 'previous+patch' (no guard, no interval), as 'cnn' and 'cnn+patch'."""
    names = {v.name: v for v in default_variants({"cnn-w8": "m.pt"})}
    scene = builtin_scene("fixed-electrode")
    alone = names["previous"].apply(scene, 5)
    patched = names["previous+patch"].apply(scene, 5)
    for s in (alone, patched):
        assert s.solver.incremental and s.mechanics.backend == "fem"
        assert s.mechanics.predictor == "previous" and s.mechanics.full_every == 10000
        assert s.mechanics.guard_tolerance is not None and s.mechanics.guard_tolerance > 1e9
    assert alone.mechanics.correction == "none" and patched.mechanics.correction == "patch"
    # the engine's incremental default keeps its patch
    assert names["fem-incremental"].apply(scene, 5).mechanics.correction == "patch"
    assert {"cnn-w8+patch", "previous+patch"} <= set(names)
