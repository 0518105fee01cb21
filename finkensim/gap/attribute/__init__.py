"""Attribute: which unmodelled effect explains a gap. The effect catalogue (:mod:`.effects`, :mod:`.effects_radio`),
the parameter fits (:mod:`.fits`), greedy forward selection and the verdict (:mod:`.selection`), and the parsimony
rules for catch-alls (:mod:`.parsimony`, :mod:`.stated`)."""
