*
masksUINT8*
scoresFP322