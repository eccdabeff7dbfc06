"""Path error against the painted reference (the paper's Table I), reports and plots."""
