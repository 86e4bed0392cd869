"""Reports of scenario runs: plots, summary.json, JUnit XML, an index page."""
