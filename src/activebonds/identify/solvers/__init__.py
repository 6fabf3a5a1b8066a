"""The solvers: exact linear least squares and Levenberg-Marquardt over structured normal equations, and the refinement that runs them in stages."""
