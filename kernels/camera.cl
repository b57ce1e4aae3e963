/* camera.cl: placeholder */
