"""Peer simulators on the comparison workload. Runs in ``.venv-peers`` (torch, vmas; no finkensim needed)."""
