"""Exports of an estimate: Lanelet2 OSM map (``osm``) and PNG plot (``plot``)."""
