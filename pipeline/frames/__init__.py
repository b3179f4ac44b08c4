"""The compositor (§3): camera paths with ray-traced direct light and specular over the illumination
map, eye adaptation and tone mapping, EXR/PNG/MP4 files, and the frames as a viewer perceives them."""
