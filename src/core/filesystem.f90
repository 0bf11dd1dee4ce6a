!> File-system helpers: sorted directory listings and existence checks.
!>
!> Usage:
!>     call list_directory("shapes/", names, error)   ! sorted names, hidden entries skipped
module anm_core_filesystem
   use, intrinsic :: iso_c_binding, only: c_char, c_int, c_null_char
   use anm_core_error, only: error_type, fatal_error, error_code
   implicit none
   private

   public :: list_directory, is_directory, join_path, base_name, make_directory

   !> A variable-length string, element of name lists.
   type, public :: string_type
      !> The text.
      character(len=:), allocatable :: s
   end type string_type

   interface
      function c_list_dir(dir, buf, buflen) bind(c, name="anm_list_dir") result(count)
         import :: c_char, c_int
         character(kind=c_char), intent(in) :: dir(*)
         character(kind=c_char), intent(out) :: buf(*)
         integer(c_int), value, intent(in) :: buflen
         integer(c_int) :: count
      end function c_list_dir
      function c_make_directory(path) bind(c, name="anm_make_directory") result(stat)
         import :: c_char, c_int
         character(kind=c_char), intent(in) :: path(*)
         integer(c_int) :: stat
      end function c_make_directory
   end interface

contains

   !> Create a directory and its missing parents (like mkdir -p).
   subroutine make_directory(path, error)
      !> Directory path.
      character(len=*), intent(in) :: path
      !> Error naming the path.
      type(error_type), allocatable, intent(out) :: error
      integer(c_int) :: stat
      stat = c_make_directory(trim(path)//c_null_char)
      if (stat /= 0) call fatal_error(error, trim(path)//": cannot create directory (errno "// &
                                      char(48 + mod(stat / 10, 10))//char(48 + mod(stat, 10))//")", error_code%io)
   end subroutine make_directory

   !> Names in directory `dir`, sorted, hidden entries (leading '.') skipped.
   subroutine list_directory(dir, names, error)
      !> Directory path.
      character(len=*), intent(in) :: dir
      !> Sorted entry names.
      type(string_type), allocatable, intent(out) :: names(:)
      !> Error: the directory cannot be read.
      type(error_type), allocatable, intent(out) :: error
      character(kind=c_char), allocatable :: buf(:)
      integer(c_int) :: count
      integer :: buflen, i, start, k
      type(string_type) :: tmp

      buflen = 65536
      do
         allocate (buf(buflen))
         count = c_list_dir(trim(dir)//c_null_char, buf, int(buflen, c_int))
         if (count /= -2) exit
         deallocate (buf)
         buflen = buflen * 4
      end do
      if (count < 0) then
         call fatal_error(error, trim(dir)//": cannot open directory", error_code%io)
         return
      end if
      allocate (names(count))
      start = 1
      k = 0
      do i = 1, size(buf)
         if (k == count) exit
         if (buf(i) == new_line('a')) then
            k = k + 1
            allocate (character(len=i - start) :: names(k)%s)
            names(k)%s = transfer(buf(start:i - 1), names(k)%s)
            start = i + 1
         end if
      end do
      ! insertion sort (directories hold at most thousands of entries)
      do i = 2, count
         tmp = names(i)
         k = i - 1
         do while (k >= 1)
            if (llt(tmp%s, names(k)%s)) then
               names(k + 1) = names(k)
               k = k - 1
            else
               exit
            end if
         end do
         names(k + 1) = tmp
      end do
   end subroutine list_directory

   !> True when `path` names a directory that can be listed.
   function is_directory(path) result(isdir)
      !> Path to test.
      character(len=*), intent(in) :: path
      logical :: isdir
      character(kind=c_char) :: buf(1)
      integer(c_int) :: count
      count = c_list_dir(trim(path)//c_null_char, buf, 0_c_int)
      isdir = count /= -1
   end function is_directory

   !> dir // "/" // name, without doubling the separator.
   pure function join_path(dir, name) result(path)
      !> Directory.
      character(len=*), intent(in) :: dir
      !> Entry name.
      character(len=*), intent(in) :: name
      character(len=:), allocatable :: path
      if (len_trim(dir) == 0) then
         path = name
      else if (dir(len_trim(dir):len_trim(dir)) == "/") then
         path = trim(dir)//name
      else
         path = trim(dir)//"/"//name
      end if
   end function join_path

   !> Last component of a path.
   pure function base_name(path) result(name)
      !> Path.
      character(len=*), intent(in) :: path
      character(len=:), allocatable :: name
      integer :: i
      i = index(trim(path), "/", back=.true.)
      name = trim(path(i + 1:))
   end function base_name
end module anm_core_filesystem
