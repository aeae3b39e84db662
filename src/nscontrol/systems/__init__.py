"""Models, validated at construction: mechanical systems with impacts, linear hybrid systems,
Lur'e systems, piecewise-affine, Filippov and switched affine systems."""
