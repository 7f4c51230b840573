"""Connected components of a small graph given as items and pairs (scipy.sparse.csgraph).

One piece for the groupings the package makes: border points merged into one node
(``export/osm.py``), connectors into intersections (``fleet/prior_map.py``), AV2 junction
segments (``realdata/av2.py``), SUMO nodes into real junctions (``scenarios/sumo_gt.py``).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ['components']


def components(items, pairs) -> list[list]:
    """The connected components of the undirected graph on ``items`` (hashable, comparable;
    duplicates count once) with the edges ``pairs`` (both ends among ``items``): each a list
    in the order the items came, the lists ordered by their smallest item."""
    items = list(dict.fromkeys(items))
    index = {k: i for i, k in enumerate(items)}
    edges = np.array([(index[a], index[b]) for a, b in pairs], np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(len(items),) * 2)
    _, label = connected_components(graph, directed=False)
    groups: dict = {}
    for k, lab in zip(items, label):
        groups.setdefault(int(lab), []).append(k)
    return sorted(groups.values(), key=min)
