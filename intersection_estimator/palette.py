"""One palette for every drawing of an estimate: the PNG (``export/plot.py``) and the RViz /
Foxglove markers (``msg_adapters/markers.py``) take their colours from here, so that a lane
has the same colour wherever a user looks at it.

Lanes by kind (the hue is the meaning): entering green, leaving blue, connector orange.
Drawing elements have one RGBA each; the PNG draws on white, the markers on RViz's dark
background, so the neutral elements (borders, arrows, text) differ by medium only in
:data:`PNG_NEUTRAL`, never the lane colours.
"""

from __future__ import annotations

__all__ = ['KIND_RGBA', 'RGBA', 'PNG_NEUTRAL', 'kind_rgba', 'rgb_hex']

#: RGBA of a lanelet by ``Lanelet.kind`` (center line, and the PNG's borders).
KIND_RGBA = {
    'entering': (0.2, 0.8, 0.3, 0.9),
    'leaving': (0.2, 0.5, 1.0, 0.9),
    'connector': (1.0, 0.6, 0.1, 0.9),
}
#: a kind this palette does not know (never produced today, drawn rather than failing)
UNKNOWN_KIND = (0.6, 0.3, 0.8, 0.9)

#: RGBA per drawing element (markers; the PNG uses the same keys where it draws them).
RGBA = {
    'center': (1.0, 0.2, 0.2, 1.0),
    'ego': (0.85, 0.1, 0.85, 1.0),
    'arm': (0.7, 0.7, 0.7, 0.8),
    **KIND_RGBA,
    'bound': (1.0, 1.0, 1.0, 0.9),
    'virtual_bound': (1.0, 1.0, 1.0, 0.3),
    'arrow': (1.0, 1.0, 1.0, 0.7),
    'text': (1.0, 1.0, 1.0, 1.0),
    'changed': (0.84, 0.15, 0.16, 1.0),     # map lanes a change concerns (fleet PNG: tab:red)
    'added': (1.0, 0.5, 0.05, 1.0),         # an arm the map lacks (fleet PNG: tab:orange)
}

#: the neutral elements on the PNG's white background (white on white would vanish)
PNG_NEUTRAL = {'arm': (0.0, 0.0, 0.0, 1.0), 'detections': (0.75, 0.75, 0.75, 1.0),
               'tracked': (0.55, 0.55, 0.55, 1.0), 'ground_truth': (0.0, 0.0, 0.0, 1.0)}


def kind_rgba(kind: str) -> tuple:
    """RGBA of a lanelet kind ('entering' / 'leaving' / 'connector')."""
    return KIND_RGBA.get(kind, UNKNOWN_KIND)


def rgb_hex(rgba) -> str:
    """'#rrggbb' of an RGBA tuple (matplotlib colour without the alpha)."""
    return '#' + ''.join(f'{int(round(255 * max(0.0, min(1.0, c)))):02x}' for c in rgba[:3])
