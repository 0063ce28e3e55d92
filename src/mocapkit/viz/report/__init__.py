"""The capture report's parts: plotly figures (`figures`) and the offline HTML page (`page`).

`mocapkit.pipelines.report.build_report` puts them together for a result folder.
"""
