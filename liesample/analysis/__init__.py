"""Analysis: comparison with exact references (MCSE z-scores, ESS, R-hat) and plots."""
