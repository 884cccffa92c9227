/* The one error enumeration of the firmware: 0 is success, negative values
 * are errors. Table commands report their reason codes (common/interface.toml,
 * PIEZO_TABLE_REASON_*) beside it; piezo_strerror() names both. */
#ifndef PIEZO_ERR_H
#define PIEZO_ERR_H

#include <stdint.h>

enum piezo_err {
    PIEZO_OK = 0,
    PIEZO_EINVAL = -1,  /* an argument or coefficient is out of its documented range */
    PIEZO_ERANGE = -2,  /* a count exceeds the caller's buffer or a compile-time limit */
    PIEZO_EORDER = -3,  /* thresholds or levels not in the required order */
    PIEZO_EPERM = -4,   /* not allowed in this state or session (locked, not the owner) */
    PIEZO_EKEY = -5,    /* wrong unlock key */
    PIEZO_EBUSY = -6,   /* refused for now (unlock backoff or lockout, a commit pending) */
    PIEZO_EIO = -7      /* storage or transport failed */
};

/** A short description of a piezo_err code (never NULL). */
const char *piezo_strerror(int err);

/** The name of a table reason code (interface.toml [table.reasons]), never NULL. */
const char *piezo_table_reason_str(uint16_t reason);

#endif /* PIEZO_ERR_H */
