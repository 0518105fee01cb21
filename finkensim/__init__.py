"""finkensim: fast simulator of FINken quadcopter swarms with realistic walls and sensors."""
__version__ = "0.1.0"
