"""What a run hands on: per-point labels, elements.json, spaces.geojson, space statistics, the floor plan and the report."""
