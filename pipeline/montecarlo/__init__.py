"""Monte Carlo of missions (eq. 39): dispersed samples of one mission spec, run on Dask, each
judged against the requirement, and the verdict at a stated confidence (eq. 38)."""
