"""Models, validated at construction: mechanical systems with impacts, Lur'e systems,
piecewise-affine, Filippov and switched affine systems."""
