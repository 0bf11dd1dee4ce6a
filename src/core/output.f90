!> Safe output files. Every file a run writes goes first to a temporary name in the target
!> folder (`FINAL.anm-tmp-PID`, unique per process), is checked on every write and on close, and
!> is renamed over the final name only when all the files of the set are complete, under an
!> exclusive lock on the folder, so that one run's outputs replace the earlier set together and
!> two runs writing the same names never mix. On error the temporaries are removed and the earlier
!> files stay as they were. Temporaries of killed runs (dead PID) are removed by the next run
!> writing to the same folder. docs/reliability.md lists what each guard promises.
!>
!> Usage:
!>     call check_writable(dir, error)              ! before the long work
!>     call set%add(join_path(dir, "model.h5"), tmp) ! write to tmp
!>     ...
!>     call set%commit(error)                        ! or: call set%discard()
module anm_core_output
   use, intrinsic :: iso_c_binding, only: c_char, c_int, c_long_long, c_null_char, c_funptr, c_null_funptr
   use anm_core_kinds, only: i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_filesystem, only: list_directory, string_type, join_path, base_name
   implicit none
   private

   public :: output_set_type, write_text_file, check_writable, ignore_file_size_signal, remove_file, temp_name, &
      & remove_stale_temps, directory_of, temp_tag, check_complete, file_size

   !> Marker in temporary file names: FINAL//temp_tag//PID.
   character(len=*), parameter :: temp_tag = ".anm-tmp-"

   !> Files written to temporary names, renamed to their final names together.
   type :: output_set_type
      !> Final and temporary names.
      type(string_type), allocatable :: final(:), temp(:)
      !> Files of an earlier run that this set replaces without a new version (removed at commit).
      type(string_type), allocatable :: obsolete(:)
   contains
      !> Register a final name; returns the temporary name to write to.
      procedure :: add => set_add
      !> Register an earlier file to remove when the set is committed.
      procedure :: retire => set_retire
      !> Rename every temporary to its final name (under a lock on the folder).
      procedure :: commit => set_commit
      !> Remove every temporary (after an error).
      procedure :: discard => set_discard
   end type output_set_type

   interface
      function c_rename(old, new) bind(c, name="rename") result(stat)
         import :: c_char, c_int
         character(kind=c_char), intent(in) :: old(*), new(*)
         integer(c_int) :: stat
      end function c_rename
      function c_unlink(path) bind(c, name="unlink") result(stat)
         import :: c_char, c_int
         character(kind=c_char), intent(in) :: path(*)
         integer(c_int) :: stat
      end function c_unlink
      function c_getpid() bind(c, name="getpid") result(pid)
         import :: c_int
         integer(c_int) :: pid
      end function c_getpid
      function c_signal(signum, handler) bind(c, name="signal") result(old)
         import :: c_int, c_funptr
         integer(c_int), value, intent(in) :: signum
         type(c_funptr), value, intent(in) :: handler
         type(c_funptr) :: old
      end function c_signal
      function c_lock_dir(dir) bind(c, name="anm_lock_dir") result(fd)
         import :: c_char, c_int
         character(kind=c_char), intent(in) :: dir(*)
         integer(c_int) :: fd
      end function c_lock_dir
      subroutine c_unlock_dir(fd) bind(c, name="anm_unlock_dir")
         import :: c_int
         integer(c_int), value, intent(in) :: fd
      end subroutine c_unlock_dir
      function c_fsync_path(path) bind(c, name="anm_fsync_path") result(stat)
         import :: c_char, c_int
         character(kind=c_char), intent(in) :: path(*)
         integer(c_int) :: stat
      end function c_fsync_path
      function c_file_size(path) bind(c, name="anm_file_size") result(size)
         import :: c_char, c_long_long
         character(kind=c_char), intent(in) :: path(*)
         integer(c_long_long) :: size
      end function c_file_size
      function c_process_alive(pid) bind(c, name="anm_process_alive") result(alive)
         import :: c_int
         integer(c_int), value, intent(in) :: pid
         integer(c_int) :: alive
      end function c_process_alive
   end interface

contains

   !> Ignore SIGXFSZ (file-size limit, `ulimit -f`) so that a write beyond the limit fails with
   !> EFBIG and is reported as an error, instead of killing the program (gfortran's runtime would
   !> otherwise turn the signal into a crash with a backtrace).
   subroutine ignore_file_size_signal()
      integer(c_int), parameter :: sigxfsz = 25   ! Linux (x86, ARM, RISC-V, POWER)
      type(c_funptr) :: old
      ! SIG_IGN is the handler address 1
      old = c_signal(sigxfsz, transfer(1_8, c_null_funptr))
   end subroutine ignore_file_size_signal

   !> Write `text` (lines separated by new_line) as the file `path`, safely: to a unique temporary
   !> in the same folder, every write and the close checked, then renamed; on error the temporary is
   !> removed, an earlier file is kept and the error names `path`.
   subroutine write_text_file(path, text, error)
      !> Final file name.
      character(len=*), intent(in) :: path
      !> The whole content.
      character(len=*), intent(in) :: text
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      type(output_set_type) :: set
      character(len=:), allocatable :: tmp
      character(len=512) :: msg
      integer :: unit, stat
      call set%add(path, tmp)
      open (newunit=unit, file=tmp, access="stream", form="formatted", status="replace", action="write", &
            iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, path//": cannot open for writing ("//trim(msg)//")", error_code%io)
         call set%discard()
         return
      end if
      write (unit, '(a)', advance="no", iostat=stat, iomsg=msg) text
      if (stat /= 0) then
         call fatal_error(error, path//": write failed ("//trim(msg)//")", error_code%io)
      else
         call check_complete(unit, tmp, path, error)
      end if
      if (allocated(error)) then
         close (unit, iostat=stat)
         call set%discard()
         return
      end if
      close (unit, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, path//": error closing the file ("//trim(msg)//")", error_code%io)
         call set%discard()
         return
      end if
      call set%commit(error)
   end subroutine write_text_file

   !> Size of a file in bytes as the file system has it (-1 when it cannot be read).
   function file_size(path) result(size)
      !> File name.
      character(len=*), intent(in) :: path
      integer(i8) :: size
      size = int(c_file_size(trim(path)//c_null_char), i8)
   end function file_size

   !> Check that everything written to `unit` (opened on file `path` with access="stream") reached
   !> the file: flushes it and compares the position with the size on disk. gfortran's runtime
   !> does not report a short write (disk full, file-size limit) through iostat, so every writer
   !> calls this before closing. Errors name `shown`.
   subroutine check_complete(unit, path, shown, error)
      !> Open unit (stream access).
      integer, intent(in) :: unit
      !> File name of the unit.
      character(len=*), intent(in) :: path
      !> Name for messages.
      character(len=*), intent(in) :: shown
      !> Error: the file is shorter than what was written.
      type(error_type), allocatable, intent(out) :: error
      integer(i8) :: pos, size
      integer :: stat
      character(len=512) :: msg
      character(len=24) :: a, b
      flush (unit, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, shown//": write failed ("//trim(msg)//")", error_code%io)
         return
      end if
      inquire (unit=unit, pos=pos)
      size = file_size(path)
      if (size /= pos - 1) then
         write (a, '(i0)') max(0_i8, size)
         write (b, '(i0)') pos - 1
         call fatal_error(error, shown//": write failed: "//trim(a)//" of "//trim(b)// &
                          " bytes reached the disk (disk full or file-size limit)", error_code%io)
      end if
   end subroutine check_complete

   !> Folder part of a path ("." when there is none).
   pure function directory_of(path) result(dir)
      !> File path.
      character(len=*), intent(in) :: path
      character(len=:), allocatable :: dir
      integer :: k
      k = index(trim(path), "/", back=.true.)
      if (k == 0) then
         dir = "."
      else if (k == 1) then
         dir = "/"
      else
         dir = path(1:k - 1)
      end if
   end function directory_of

   !> Temporary name of this process for final name `path`, in the same folder.
   function temp_name(path) result(tmp)
      !> Final name.
      character(len=*), intent(in) :: path
      character(len=:), allocatable :: tmp
      character(len=16) :: pid
      write (pid, '(i0)') c_getpid()
      tmp = trim(path)//temp_tag//trim(pid)
   end function temp_name

   !> Remove a file if it exists (no error when it does not).
   subroutine remove_file(path)
      !> File name.
      character(len=*), intent(in) :: path
      integer(c_int) :: stat
      stat = c_unlink(trim(path)//c_null_char)
   end subroutine remove_file

   !> Check that files can be created in folder `dir` (it must exist): creates and removes a probe.
   subroutine check_writable(dir, error)
      !> Output folder.
      character(len=*), intent(in) :: dir
      !> Error naming the folder and the reason.
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: probe
      character(len=512) :: msg
      integer :: unit, stat, stat2
      probe = temp_name(join_path(dir, ".anm-write-check"))
      open (newunit=unit, file=probe, status="replace", action="write", iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, trim(dir)//": output folder is not writable ("//trim(msg)//")", error_code%io)
         return
      end if
      write (unit, '(a)', iostat=stat, iomsg=msg) "anm write check"
      if (stat == 0) flush (unit, iostat=stat, iomsg=msg)
      close (unit, status="delete", iostat=stat2)
      call remove_file(probe)
      if (stat /= 0) call fatal_error(error, trim(dir)//": cannot write in the output folder ("//trim(msg)//")", &
                                      error_code%io)
   end subroutine check_writable

   !> Remove temporaries `NAME.anm-tmp-PID` in `dir` left by processes that no longer exist (a run
   !> killed while writing). Temporaries of running processes are kept.
   subroutine remove_stale_temps(dir)
      !> Output folder.
      character(len=*), intent(in) :: dir
      type(string_type), allocatable :: names(:)
      type(error_type), allocatable :: error
      integer :: i, k, pid, stat
      call list_directory(dir, names, error)
      if (allocated(error)) return
      do i = 1, size(names)
         k = index(names(i)%s, temp_tag, back=.true.)
         if (k == 0) cycle
         read (names(i)%s(k + len(temp_tag):), *, iostat=stat) pid
         if (stat /= 0) cycle
         if (verify(names(i)%s(k + len(temp_tag):), "0123456789") /= 0) cycle
         if (c_process_alive(int(pid, c_int)) == 0) call remove_file(join_path(dir, names(i)%s))
      end do
   end subroutine remove_stale_temps

   !> Register final name `path`; `tmp` is the name to write to.
   subroutine set_add(self, path, tmp)
      !> Output set.
      class(output_set_type), intent(inout) :: self
      !> Final name.
      character(len=*), intent(in) :: path
      !> Temporary name to write.
      character(len=:), allocatable, intent(out) :: tmp
      type(string_type), allocatable :: f(:), t(:)
      integer :: n
      n = 0
      if (allocated(self%final)) n = size(self%final)
      allocate (f(n + 1), t(n + 1))
      if (n > 0) then
         f(:n) = self%final
         t(:n) = self%temp
      end if
      tmp = temp_name(path)
      f(n + 1)%s = trim(path)
      t(n + 1)%s = tmp
      call move_alloc(f, self%final)
      call move_alloc(t, self%temp)
   end subroutine set_add

   !> Register `path`, a file of an earlier run that the set replaces without writing a new
   !> version (e.g. the VRML file of a run that now writes none): it is removed by `commit`,
   !> under the same lock as the renames, and left in place if the set is discarded.
   subroutine set_retire(self, path)
      !> Output set.
      class(output_set_type), intent(inout) :: self
      !> File to remove at commit.
      character(len=*), intent(in) :: path
      type(string_type), allocatable :: f(:)
      integer :: n
      n = 0
      if (allocated(self%obsolete)) n = size(self%obsolete)
      allocate (f(n + 1))
      if (n > 0) f(:n) = self%obsolete
      f(n + 1)%s = trim(path)
      call move_alloc(f, self%obsolete)
   end subroutine set_retire

   !> Make every temporary durable (fsync) and rename it to its final name; the renames of one
   !> set happen under an exclusive lock on the (first file's) folder, so that concurrent runs
   !> replace whole sets. Retired files are removed under the same lock, after the renames.
   !> On error every remaining temporary is removed.
   subroutine set_commit(self, error)
      !> Output set.
      class(output_set_type), intent(inout) :: self
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      integer :: i
      integer(c_int) :: fd, stat
      character(len=8) :: num
      if (.not. allocated(self%final)) return
      do i = 1, size(self%final)
         stat = c_fsync_path(self%temp(i)%s//c_null_char)
         if (stat /= 0) then
            write (num, '(i0)') stat
            call fatal_error(error, self%final(i)%s//": cannot flush the file to disk (errno "//trim(num)//")", &
                             error_code%io)
            call self%discard()
            return
         end if
      end do
      fd = c_lock_dir(directory_of(self%final(1)%s)//c_null_char)
      do i = 1, size(self%final)
         if (c_rename(self%temp(i)%s//c_null_char, self%final(i)%s//c_null_char) /= 0) then
            call fatal_error(error, self%final(i)%s//": cannot rename "//base_name(self%temp(i)%s)// &
                             " to the final name", error_code%io)
            exit
         end if
      end do
      if (.not. allocated(error) .and. allocated(self%obsolete)) then
         do i = 1, size(self%obsolete)
            call remove_file(self%obsolete(i)%s)
         end do
      end if
      call c_unlock_dir(fd)
      call self%discard()
   end subroutine set_commit

   !> Remove every temporary of the set that still exists and forget the set.
   subroutine set_discard(self)
      !> Output set.
      class(output_set_type), intent(inout) :: self
      integer :: i
      if (allocated(self%obsolete)) deallocate (self%obsolete)
      if (.not. allocated(self%temp)) return
      do i = 1, size(self%temp)
         call remove_file(self%temp(i)%s)
      end do
      deallocate (self%final, self%temp)
   end subroutine set_discard
end module anm_core_output
