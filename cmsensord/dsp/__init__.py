"""Pure signal processing: arrays in, arrays out, state carried explicitly."""
