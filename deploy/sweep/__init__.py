"""`enclose sweep`: a grid of real runs, resumable.

`command` registers the subcommand and runs the grid; `spec` reads the sweep file,
`runner` runs one cell (`parallel`: several here, `cluster`: on Dask), `table`,
`summary`, `figures` and `verdict` turn the cells' directories into results.
"""
