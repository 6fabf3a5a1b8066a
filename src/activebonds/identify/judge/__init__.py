"""The judge: what a model predicts from recorded states beside the zero-force predictor, the scores and verdicts, and which fitted numbers the data determine."""
