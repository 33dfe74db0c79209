"""lidarcam's real-rig side and command line: ``lidarcam.rig`` (dataset folders, importers, bags, detection,
segmentation, overlays, reports) and ``lidarcam.cli`` (the ``lidarcam`` command). The calibration library is
``calib_core`` and the simulator ``simulate``."""
