"""Detect: where the real readings disagree with the model beyond chance. The sensors' range limits against the logs
(:mod:`.limits`), censored scoring of lost echoes (:mod:`.censoring`), and the block bootstrap and false-discovery
control that decide which gaps are significant (:mod:`.stats`), the configured model's gap per sensor
(:mod:`.significance`) and whether the held-out readings can decide it (:mod:`.sufficiency`: no absurd gap, "too
little data to decide")."""
