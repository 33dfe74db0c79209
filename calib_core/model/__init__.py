"""The likelihood's home: every residual term and its Jacobian (ranges, planes, the exact and the lower-bound outline,
image corners, the intrinsics prior, the mounting prior, the plausibility test) and the costs composed of them (the
``lidarcam`` score, its linearisation). The stages above (the consensus search, the choice, the polish, the joint
solve, the covariance) compose these terms; none writes a term of its own."""
