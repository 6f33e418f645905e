"""Characters keyfill knows by name: their skeletons and the animation variables models see."""
