/* Directory listing for Fortran (no intrinsic exists). Writes the names of the regular entries of
 * `dir` (not starting with '.') into `buf`, each terminated by '\n'. Returns the number of names,
 * -1 if the directory cannot be opened, -2 if `buf` is too small. */
#include <dirent.h>
#include <string.h>

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
