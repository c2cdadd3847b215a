"""suspid: identify vehicle suspension parameters (masses, springs, dampers) from sensor data.

Layout
------
suspid.models       the physics: quarter1, quarter2, half4 (eqs. 1-7 of the seed paper), effects
suspid.simulate     exact (modal, first-order-hold) and general (ODE) simulation
suspid.excitation   roads: initial state, curb, speed bump, ISO 8608 random road, measured
suspid.io           measurement CSV reading and writing
suspid.can          the bus side shared by node and estimator: DBC, CRC, codec, log formats
suspid.cli          one module per ``suspid`` subcommand
firmware_sim        the simulated sensor node (scheduler, sensors, faults, transports)
estimator           decoder, identifier, streaming monitor, alerts, EKF baseline, diagnosis
"""
__version__ = "0.1.0"
