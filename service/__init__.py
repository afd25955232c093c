"""service: what runs. The one command line (`cli`), the Zenoh schedule service
(`zenoh_service`), workspace sweeps on Dask with their report (`sweep`), the gap workflow's
baseline and report (`gap`) and the HTML pieces the reports share (`html`). Imports `posedyn`
and `absorber`; nothing imports it."""
