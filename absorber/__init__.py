"""absorber: MRF absorber field model and coil, tuning policies, active damping and per-pose
schedules. Imports `posedyn`, never `service`. (Contents arrive with the absorber issues.)"""
