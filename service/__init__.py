"""service: the Zenoh schedule service and its client. Imports `posedyn` and `absorber`.
(Contents arrive with the service issue.)"""
