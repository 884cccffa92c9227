/* Return codes of the core: 0 is success, negative values are errors. */
#ifndef PIEZO_ERR_H
#define PIEZO_ERR_H

enum piezo_err {
    PIEZO_OK = 0,
    PIEZO_EINVAL = -1,  /* an argument or coefficient is out of its documented range */
    PIEZO_ERANGE = -2,  /* a count exceeds the caller's buffer or a compile-time limit */
    PIEZO_EORDER = -3   /* thresholds or levels not in the required order */
};

#endif /* PIEZO_ERR_H */
