"""The report page's stylesheet (inline in the page: the report is one self-contained file)."""

__all__ = ["CSS"]

CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#222;background:#fafafa}
main{max-width:1240px;margin:0 auto;padding:12px 20px 40px}h1{font-size:22px;margin:8px 0 2px}
h2{font-size:17px;border-bottom:1px solid #ddd;padding-bottom:3px;margin-top:28px}.sub{color:#555;margin:0 0 10px}
nav a{margin-right:12px;color:#2a5db0;text-decoration:none;font-size:13px}
.cards{display:flex;flex-wrap:wrap;gap:10px;margin:10px 0}.card{background:#fff;border:1px solid #ddd;
border-radius:6px;padding:6px 12px}.card b{display:block;font-size:18px}.card span{color:#666;font-size:12px}
figure{margin:6px 0}figcaption{font-size:12.5px;color:#444;max-width:1100px}img{display:block;max-width:100%}svg.graph{display:block;max-width:100%;height:auto}
.grid{display:grid;gap:8px}.grid.views{grid-template-columns:repeat(auto-fill,minmax(118px,1fr))}
.grid.jih{grid-template-columns:repeat(auto-fill,minmax(120px,1fr))}
.grid.panels{grid-template-columns:repeat(3,226px)}.grid figure,.row figure{margin:0;background:#fff;
border:2px solid #e4e4e4;padding:3px}.grid figure img{width:100%}.grid figure img+img{margin-top:3px}
.grid figcaption,.row figcaption{font-size:11px;word-break:break-all}figure.ref{border-color:#d62728}
.row{display:flex;flex-wrap:wrap;gap:8px;margin-bottom:8px}.row figure{max-width:330px}
.grid figure img.cmf{width:50%;margin-top:3px}.badge{background:#d62728;color:#fff;border-radius:3px;
padding:0 4px;font-size:10px}.badge.grey{background:#888}table{border-collapse:collapse;background:#fff;margin:6px 0}
td,th{border:1px solid #ddd;padding:3px 8px;font-size:12.5px;text-align:right}th{background:#f0f0f0}
table.kv th{text-align:left;font-weight:normal;color:#444}.note{font-size:12.5px;color:#555;max-width:1100px}
.side{display:flex;flex-wrap:wrap;gap:14px;align-items:flex-start}.side img{max-width:640px}.side figcaption{width:100%}
.legend{list-style:none;padding:0;margin:0;font-size:12px;columns:2}.sw{display:inline-block;width:12px;height:12px;
margin-right:5px;vertical-align:middle;border:1px solid #999}details{margin:6px 0}code{font-size:12px}
.tables{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}th.group{text-align:left;font-weight:bold}
.viewer{position:relative}.viewer canvas{display:block;width:100%;height:520px;background:#f2f2f2;
border:1px solid #ddd;border-radius:4px;touch-action:none}.viewer-loading{position:absolute;left:0;right:0;top:0;
height:520px;display:flex;align-items:center;justify-content:center;font-size:15px;color:#555;pointer-events:none}
.viewer:not([data-state="loading"]) .viewer-loading{display:none}.viewer-modes{display:flex;flex-wrap:wrap;gap:14px;margin:6px 0;font-size:13px}
.callout{background:#fff8e1;border:1px solid #e8c65a;border-radius:4px;padding:6px 10px;max-width:1100px;
font-size:13px}.closeup .row figure{max-width:330px}.scale{display:flex;align-items:flex-start;gap:10px;font-size:12px;
margin:6px 0}.scale .bar{display:block;width:240px;height:12px;border:1px solid #999}.scale .ticks{display:flex;
justify-content:space-between;width:242px}
"""
