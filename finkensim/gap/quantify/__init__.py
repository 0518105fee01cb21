"""Quantify: how far the gap shrinks and how sure the fit is. The shrink measure a wider predictive cannot fake
(:mod:`.shrink`), the data-driven correction of what no effect explains (:mod:`.correction`), the fitted parameters'
bootstrap intervals (:mod:`.intervals`) and the calibrated scenario (:mod:`.calibrate`)."""
