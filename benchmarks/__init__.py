"""finkensim benchmarks: ``python -m benchmarks.run [--quick]`` (``make bench``); peers via ``make bench-peers``."""
