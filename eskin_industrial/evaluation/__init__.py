"""Scoring the detection methods on scenes with ground truth: the corpus, the metrics,
the suite, the sweeps and charts, and the learned method's training."""
