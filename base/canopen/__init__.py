"""CANopen numbers and codecs shared by the master (drivers) and the simulated firmware: object ids, CiA 402 words, EDS loading."""
