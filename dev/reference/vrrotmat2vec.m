function r = vrrotmat2vec(R)
% Stand-in (written for this check): axis-angle [ax ay az angle] (row) of a rotation matrix.
c = max(-1, min(1, (trace(R) - 1) / 2));
angle = acos(c);
if angle < 1e-12
  r = [1 0 0 0];
  return
end
if pi - angle < 1e-6
  [V, D] = eig((R + R') / 2);
  [~, k] = max(diag(D));
  ax = V(:, k)';
  s = [R(3,2)-R(2,3), R(1,3)-R(3,1), R(2,1)-R(1,2)];
  if s * ax' < 0, ax = -ax; end
else
  ax = [R(3,2)-R(2,3), R(1,3)-R(3,1), R(2,1)-R(1,2)] / (2 * sin(angle));
end
r = [ax / norm(ax), angle];
end
