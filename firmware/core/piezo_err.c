#include "piezo_err.h"

#include "piezo_interface.h"

const char *piezo_strerror(int err)
{
    switch (err) {
    case PIEZO_OK: return "success";
    case PIEZO_EINVAL: return "argument or coefficient out of its documented range";
    case PIEZO_ERANGE: return "count exceeds a buffer or a compile-time limit";
    case PIEZO_EORDER: return "thresholds or levels not in the required order";
    case PIEZO_EPERM: return "not allowed in this state or session";
    case PIEZO_EKEY: return "wrong unlock key";
    case PIEZO_EBUSY: return "refused for now (unlock backoff or lockout, commit pending)";
    case PIEZO_EIO: return "storage or transport failed";
    default: return "unknown error";
    }
}

const char *piezo_table_reason_str(uint16_t reason)
{
    return reason < PIEZO_TABLE_REASON_N ? piezo_table_reason_names[reason] : "unknown reason";
}
