"""Capture planning: which board poses to add, predicted from the information each would bring (``capture``), the
rig and workspace they are drawn in (``views``), and a plan from the boards captured so far (``observed``)."""
