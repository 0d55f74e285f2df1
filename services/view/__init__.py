"""The live view in the Foxglove app (node.py) and the Foxglove export of recordings (export.py), over one conversion (convert.py)."""
