/* shade.cl: placeholder */
