"""The whole run on dask.distributed: the cluster, the stages and their records, the run itself."""
