"""The validation harness of ``finkensim gap-validate``, apart from the diagnosis it judges: withheld-effect cases
(:mod:`.cases`) recorded the way other tools record (:mod:`.conventions`), run as a resumable sweep (:mod:`.sweep`),
tabulated (:mod:`.tables`) and drawn (:mod:`.plot`); the closed loop diagnose → calibrate → diagnose
(:mod:`.calibrated`)."""
