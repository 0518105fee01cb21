"""The validation harness of ``finkensim gap-validate``, apart from the diagnosis it judges: withheld-effect cases
(:mod:`~finkensim.gap.validation.cases`) recorded the way other tools record
(:mod:`~finkensim.gap.validation.conventions`), run as a resumable sweep (:mod:`~finkensim.gap.validation.sweep`),
tabulated (:mod:`~finkensim.gap.validation.tables`) and drawn (:mod:`~finkensim.gap.validation.plot`); the closed
loop diagnose → calibrate → diagnose (:mod:`~finkensim.gap.validation.calibrated`) and what the calibration
changes in a sweep of the swarm's behaviour (:mod:`~finkensim.gap.validation.behaviour`)."""
