% Run the authors' reference (lccMinSol, its MSAC and refinement) on exported cases (a development check).
%   octave --no-gui run_reference.m REF_DIR CASES.mat OUT.mat [msac]
% With 'msac': the MSAC solution only (lccMinSol's optimisation flag off; T_all stays NaN).
% REF_DIR: the reference's Zhang_Vasconcelos folder, with its own quat2dcm.m removed and its board count read as
% size(Tp,3); the stand-ins beside this script are put first on the path.
args = argv();
ref = args{1}; in = args{2}; out = args{3};
refine = numel(args) < 4 || ~strcmp(args{4}, 'msac');
pkg load optim
addpath(genpath(fullfile(ref, 'MinimalSolution')));
addpath(fullfile(ref, 'Optimization'));
addpath(fullfile(ref, 'Rotation'));
addpath(fileparts(mfilename('fullpath')));
S = load(in);
n = numel(S.cases);
Ti_all = nan(4, 4, n); T_all = nan(4, 4, n); inl_all = zeros(n, 12); ok = zeros(n, 1);
for k = 1:n
  c = S.cases{k};
  Pl = c.Pl;
  if ~iscell(Pl), Pl = num2cell(Pl, 1); end
  try
    if refine
      [T, r, inl, Ti] = lccMinSol(c.Tp, Pl);
    else
      [~, ~, inl, Ti] = lccMinSol(c.Tp, Pl, 1e-5, 0);
      T = nan(4);
    end
    Ti_all(:, :, k) = Ti; T_all(:, :, k) = T; inl_all(k, inl) = 1; ok(k) = 1;
  catch err
    fprintf('case %d: %s\n', k, err.message);
  end
  if mod(k, 5) == 0 || k == n
    save('-v7', out, 'Ti_all', 'T_all', 'inl_all', 'ok');  % written as it goes: a stopped run keeps its cases
    fprintf('%d/%d\n', k, n); fflush(stdout);
  end
end

