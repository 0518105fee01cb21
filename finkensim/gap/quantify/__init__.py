"""Quantify: how far the gap shrinks and how sure the fit is. The waterfall and the verdict (:mod:`.verdict`, with
the shrink of :mod:`finkensim.gap.attribute.shrink`), fitted values at a bound (:mod:`.bounds`), the data-driven correction of what no effect explains (:mod:`.correction`), the fitted parameters'
bootstrap intervals (:mod:`.intervals`) and the calibrated scenario (:mod:`.calibrate`)."""
