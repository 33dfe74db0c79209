function R = quat2dcm(q)
% Stand-in (written for this check): the direction cosine matrix of a unit quaternion q = [w x y z],
% as the aerospace toolbox defines it (the transpose of the active rotation of q).
w = q(1); x = q(2); y = q(3); z = q(4);
R = [w^2+x^2-y^2-z^2, 2*(x*y+w*z),     2*(x*z-w*y);
     2*(x*y-w*z),     w^2-x^2+y^2-z^2, 2*(y*z+w*x);
     2*(x*z+w*y),     2*(y*z-w*x),     w^2-x^2-y^2+z^2];
end
