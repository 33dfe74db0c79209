"""Capture planning: which board poses to add, predicted from the information each would bring (``capture``), and the
rig and workspace they are drawn in (``views``)."""
