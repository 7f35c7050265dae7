"""The compiler (Strassmair & Taylor 2014, section V.A): plans -> motions -> STNUs -> classes -> ranks."""
