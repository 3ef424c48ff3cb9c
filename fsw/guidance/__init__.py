"""Guidance: the bank-angle reference the attitude chain tracks, and the entry guidance that
commands it towards a deploy target (docs/fsw/index.md, docs/fsw/entry-guidance.md). Import from
the module that does the job:

- ``reference``: the scheduled bank profile (mode ``profile``) and the reference attitude
  built on any bank reference (``BankProfile``, ``Guidance``);
- ``npc``: the predictor-corrector entry guidance (mode ``npc``): ``EntryGuidance``, the
  driver on the rate groups, and its parameters ``PARAMS``;
- ``predictor``: the compiled 3-DOF predictor and the path-limit law it shares with the
  vehicle;
- ``corrector``: the bank-profile family, the root-finder, the deploy-altitude floor's
  search and one correction (``Corrector``);
- ``estimator``: the density and L/D scale estimates (``DensityEstimator``);
- ``lateral``: the bank reversals (``LateralLogic``);
- ``shaper``: the commanded bank shaped within the rate and acceleration limits
  (``BankShaper``), and the same law for the predictor;
- ``geometry``: the sphere geometry (planet-fixed state, great-circle angles, heading
  error, crossrange).
"""
