"""Attribute: which unmodelled effect explains a gap. The effect catalogue (:mod:`.effects`, :mod:`.effects_radio`),
the parameter fits (:mod:`.fits`) and their results (:mod:`.fit_result`), the shrink measure a wider predictive
cannot fake (:mod:`.shrink`: what a model explains), greedy forward selection (:mod:`.selection`), and the parsimony
rules for catch-alls (:mod:`.parsimony`, :mod:`.stated`)."""
