"""Map-change detection from a fleet's drives (issue 17).

One module per concern: :mod:`.prior_map` (a Lanelet2 map and the intersections of its
lane graph), :mod:`.match` (estimate <-> mapped intersection, arms by angle),
:mod:`.changes` (what one drive shows against the map), :mod:`.fuse` (several drives of
one intersection), :mod:`.engine` (local and Ray, one task per bag), :mod:`.report`
(``changes.json``, PNGs, summary table), :mod:`.edits` (prior maps with one change applied,
for tests and the benchmark) and :mod:`.cli` (the ``fleet`` subcommand).

Nothing here imports ``rclpy``; ``ray`` is imported only by the Ray engine.
"""
