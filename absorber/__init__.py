"""absorber: the devices that suppress chatter and the per-pose chain that schedules them.

`mrf` (seed 004's MRF absorber: field model and its inverse), `coil` (field to current),
`tuning` (TMD and IDVA tuning, seed 002), `coupling` (the absorber on the structure),
`active_damping` (seed 000's inertial actuator, DVF gains, virtual absorbers), `files` (their
parameter files), `chain` (the one per-pose chain every caller runs) and `gap_candidates` (the
gap workflow's effects through the absorber model). Imports `posedyn`, never `service`."""
