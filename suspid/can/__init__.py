"""The bus side shared by the sensor node and the estimator.

Modules
-------
crc         CRC-8 SAE J1850 and E2E (profile-1 style) protect/check
dbc         loading DBC files with one-line errors; suspid's DBC conventions
codec       precompiled signal packing/unpacking, quantization, sensor/status/alert frames
encoder     measurement CSV -> CAN log (``suspid encode``)
logs        CAN log formats by suffix (.log .asc .blf .trc .mf4): read_log, writers
frames      frames as NumPy arrays, read statistics, bus channels
candump     the candump -L column parser
pycan_logs  ASC, TRC, BLF, MF4 through python-can, tolerant; writers that read back
signal_map  user DBC signal -> model channel mappings (``--map``, TOML/JSON files)
bus         opening python-can buses (virtual, slcan incl. the node's pty, socketcan)
"""
