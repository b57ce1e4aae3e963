/* accumulate.cl: placeholder */
