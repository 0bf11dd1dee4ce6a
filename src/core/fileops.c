/* File-system calls Fortran has no intrinsic for (used by src/core/output.f90): a blocking
 * exclusive lock on a directory (flock, released by the kernel when the process ends, even when
 * killed), fsync of a file by name, and a check whether a process is alive. */
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>
#include <signal.h>
#include <errno.h>
#include <sys/stat.h>

/* Lock directory `dir` exclusively (waits for other holders). Returns a descriptor >= 0 to pass to
 * anm_unlock_dir, or -errno. */
int anm_lock_dir(const char *dir)
{
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return -errno;
    while (flock(fd, LOCK_EX) != 0) {
        if (errno != EINTR) { int e = errno; close(fd); return -e; }
    }
    return fd;
}

/* Release a lock taken by anm_lock_dir. */
void anm_unlock_dir(int fd)
{
    if (fd >= 0) close(fd);
}

/* Flush a closed file's data to the device (fsync). Returns 0 or errno. */
int anm_fsync_path(const char *path)
{
    int fd = open(path, O_RDONLY | O_CLOEXEC), rc = 0;
    if (fd < 0) return errno;
    if (fsync(fd) != 0) rc = errno;
    close(fd);
    return rc;
}

/* 1 if process `pid` exists (or exists but belongs to another user), 0 otherwise. */
int anm_process_alive(int pid)
{
    if (pid <= 0) return 0;
    if (kill((pid_t)pid, 0) == 0) return 1;
    return errno == EPERM ? 1 : 0;
}

/* Size in bytes of file `path` as the file system has it, -1 if it cannot be read. */
long long anm_file_size(const char *path)
{
    struct stat st;
    if (stat(path, &st) != 0) return -1;
    return (long long)st.st_size;
}
