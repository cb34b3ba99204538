"""The grounding study (`python -m wanderland_nav.study +study=grounding`): policies trained in degraded
copies of a grounded scene and cross-evaluated, as hashed, resumable cells.

`plan.py`: the cells, their hashes and the done-manifest several study processes share; `cells.py`: what each
cell does (build a degraded scene, one `train` run, evaluate one checkpoint in one environment);
`routes.py`: the grounded test routes mapped into a degraded scene's frame; `report.py`: `table.txt`,
`fig8.png` and `meshes.rrd`. Its config is typed in `compose/study_config.py` with every other entry point's.
Why a package of its own: it composes whole `train` runs (through `compose`), so it sits above the
composition root, and `compose` stays the one place that turns configs into objects.
"""
