/* raycast.cl: placeholder */
