"""The rig: device protocols, Dynamixel and GRBL drivers, cameras, config, pose, safety, doctor."""
