"""The predictive model every stage of the diagnosis uses: logged flights replayed through the simulator's geometry
(:mod:`.replay`, the walls' bulge :mod:`.bulge`), the model's parameters (:mod:`.params`), the readings' context
features (:mod:`.features`), M draws per reading (:mod:`.predictive`, bounded caches :mod:`.cache`) and the proper
scores of readings against them (:mod:`.scoring`)."""
