"""Converters for real recordings (issue 15.2): :mod:`.av2` (Argoverse 2 scenarios).
The data stay outside the repository (``../shared/realdata``); each keeps its licence."""
