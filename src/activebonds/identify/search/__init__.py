"""The search: the paper's evolution strategy and the other strategies, their operators, and the population's cost."""
