"""The shared base below every room: spatial math and kinematics, configuration schemas, CANopen tables and codecs, transports, process helpers, camera and marker models."""
