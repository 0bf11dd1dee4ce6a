/* Directory listing for Fortran (no intrinsic exists). Writes the names of the regular entries of
 * `dir` (not starting with '.') into `buf`, each terminated by '\n'. Returns the number of names,
 * -1 if the directory cannot be opened, -2 if `buf` is too small. */
#include <dirent.h>
#include <string.h>
#include <sys/stat.h>
#include <errno.h>

int anm_list_dir(const char *dir, char *buf, int buflen)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    int count = 0, used = 0;
    if (d == NULL) return -1;
    while ((e = readdir(d)) != NULL) {
        int len = (int)strlen(e->d_name);
        if (e->d_name[0] == '.') continue;
        if (used + len + 1 > buflen) { closedir(d); return -2; }
        memcpy(buf + used, e->d_name, (size_t)len);
        buf[used + len] = '\n';
        used += len + 1;
        count++;
    }
    closedir(d);
    return count;
}

/* mkdir -p: create `path` and its missing parents (mode 0755). Returns 0 on success, errno otherwise. */
int anm_make_directory(const char *path)
{
    char buf[4096];
    size_t len = strlen(path), i;
    struct stat st;
    if (len == 0 || len >= sizeof(buf)) return ENAMETOOLONG;
    memcpy(buf, path, len + 1);
    for (i = 1; i <= len; i++) {
        if (buf[i] == '/' || buf[i] == '\0') {
            char c = buf[i];
            buf[i] = '\0';
            if (stat(buf, &st) != 0) {
                if (mkdir(buf, 0755) != 0 && errno != EEXIST) return errno;
            } else if (!S_ISDIR(st.st_mode)) {
                return ENOTDIR;
            }
            buf[i] = c;
        }
    }
    return 0;
}
