"""Measures of a face animation: the seed's symmetry cost, landmark curves, lags, errors."""
