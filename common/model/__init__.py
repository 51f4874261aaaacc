"""The models of the loop: plant, LTI blocks, synthesis, drift, passivity, the clay's contact
law; numbers only, no I/O."""
