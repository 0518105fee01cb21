"""Report: the result of a diagnosis (:mod:`.result`, the spec's fields), assembled from the stages' results
(:mod:`.assemble`), and its files, ``report.json``, ``report.md`` and figures (:mod:`.write`)."""
