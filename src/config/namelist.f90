!> The namelist file as text: read once, checked to be a namelist, split into its groups with
!> their line numbers. Each configuration record reads its own group from the group's lines
!> (an internal file), so that an unknown or duplicate group, text outside a group, a bad value
!> and the line it sits on are all found here, before anything runs.
!>
!> Rules (docs/namelist.md "Errors"): a group starts with `&name` and ends with `/` (or `&end`)
!> outside a quoted string; `!` starts a comment; only the groups the program knows are allowed,
!> each at most once; any other text outside a group is an error; a binary file (an HDF5 model,
!> an image) is refused before it is parsed.
!>
!> Usage:
!>     type(namelist_file_type) :: nml
!>     call scan_namelist("job.nml", [character(len=9) :: "box", "sieves"], nml, error)
!>     ig = find_group(nml, "box")            ! 0 when the group is absent
!>     call config_error(error, nml, ig, "length", "must be > 0")   ! "job.nml:3: &box: length must be > 0"
module anm_config_namelist
   use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string, to_lower
   implicit none
   private

   public :: namelist_file_type, namelist_group_type, scan_namelist, find_group, config_error, &
      & group_read_error, group_reader, variable_line, check_finite, where_of

   !> Longest line accepted (characters).
   integer, parameter, public :: max_line = 1024

   !> One group of the file.
   type :: namelist_group_type
      !> Group name, lower case, without `&`.
      character(len=:), allocatable :: name
      !> Line of the `&name` (1-based) and of its closing `/`.
      integer :: first_line = 0, last_line = 0
      !> The group's text, one element per line, from `&name` to `/` (text outside blanked).
      character(len=max_line), allocatable :: lines(:)
   end type namelist_group_type

   !> The scanned file.
   type :: namelist_file_type
      !> File name (as given: every message starts with it).
      character(len=:), allocatable :: path
      !> Whole text of the file.
      character(len=:), allocatable :: text
      !> Groups in file order.
      type(namelist_group_type), allocatable :: groups(:)
   end type namelist_file_type

   abstract interface
      !> Reads a group's namelist from `lines` (the record's load supplies it; used to find the
      !> line of a bad value by reading growing prefixes of the group).
      subroutine group_reader(lines, stat, msg)
         !> Group text, one element per line.
         character(len=*), intent(in) :: lines(:)
         !> iostat of the read.
         integer, intent(out) :: stat
         !> iomsg of the read.
         character(len=*), intent(inout) :: msg
      end subroutine group_reader
   end interface

contains

   !> Read PATH, refuse binary content, split it into groups and refuse unknown and duplicate
   !> groups and text outside groups. Every message names the file and the line.
   subroutine scan_namelist(path, known, nml, error)
      !> Namelist file.
      character(len=*), intent(in) :: path
      !> Names of the groups the program knows (lower case).
      character(len=*), intent(in) :: known(:)
      !> The scanned file.
      type(namelist_file_type), intent(out) :: nml
      !> Error naming the file, the line and the group.
      type(error_type), allocatable, intent(out) :: error
      integer :: i, j

      nml%path = path
      call read_text(path, nml%text, error)
      if (allocated(error)) return
      call check_text(path, nml%text, error)
      if (allocated(error)) return
      call split_groups(nml, error)
      if (allocated(error)) return
      do i = 1, size(nml%groups)
         if (.not. any(known == nml%groups(i)%name)) then
            call fatal_error(error, path//":"//to_string(nml%groups(i)%first_line)//": unknown namelist group &" &
                             //nml%groups(i)%name//" (known groups: "//join(known)//")", error_code%format)
            return
         end if
         do j = 1, i - 1
            if (nml%groups(j)%name == nml%groups(i)%name) then
               call fatal_error(error, path//":"//to_string(nml%groups(i)%first_line)//": namelist group &" &
                                //nml%groups(i)%name//" given twice (first at line " &
                                //to_string(nml%groups(j)%first_line)//")", error_code%format)
               return
            end if
         end do
      end do
   end subroutine scan_namelist

   !> Index of group NAME in the file, 0 when it is absent.
   pure integer function find_group(nml, name) result(ig)
      !> The scanned file.
      type(namelist_file_type), intent(in) :: nml
      !> Group name (lower case).
      character(len=*), intent(in) :: name
      integer :: i
      ig = 0
      do i = 1, size(nml%groups)
         if (nml%groups(i)%name == name) then
            ig = i
            return
         end if
      end do
   end function find_group

   !> "FILE:LINE: &GROUP: " for variable VAR of group IG (the group's line when VAR is not
   !> written; no line when the group is absent).
   pure function where_of(nml, ig, gname, var) result(prefix)
      !> The scanned file.
      type(namelist_file_type), intent(in) :: nml
      !> Group index (0: absent).
      integer, intent(in) :: ig
      !> Group name.
      character(len=*), intent(in) :: gname
      !> Variable name (may be empty).
      character(len=*), intent(in) :: var
      character(len=:), allocatable :: prefix
      integer :: line
      line = 0
      if (ig > 0) line = variable_line(nml%groups(ig), var)
      if (line > 0) then
         prefix = nml%path//":"//to_string(line)//": &"//gname//": "
      else
         prefix = nml%path//": &"//gname//": "
      end if
   end function where_of

   !> Allocate a value error "FILE:LINE: &GROUP: VAR WHAT".
   pure subroutine config_error(error, nml, ig, gname, var, what)
      !> The error.
      type(error_type), allocatable, intent(out) :: error
      !> The scanned file.
      type(namelist_file_type), intent(in) :: nml
      !> Group index (0: absent).
      integer, intent(in) :: ig
      !> Group name.
      character(len=*), intent(in) :: gname
      !> Variable as shown (e.g. "max_width(2)"); its name up to "(" is looked up for the line.
      character(len=*), intent(in) :: var
      !> What is wrong.
      character(len=*), intent(in) :: what
      integer :: k
      k = index(var, "(")
      if (k > 1) then
         call fatal_error(error, where_of(nml, ig, gname, var(:k - 1))//var//" "//what, error_code%value)
      else
         call fatal_error(error, where_of(nml, ig, gname, var)//var//" "//what, error_code%value)
      end if
   end subroutine config_error

   !> Line (in the file) where VAR is assigned in GROUP; the group's first line if it is not.
   pure integer function variable_line(group, var) result(line)
      !> The group.
      type(namelist_group_type), intent(in) :: group
      !> Variable name.
      character(len=*), intent(in) :: var
      character(len=:), allocatable :: low, v
      integer :: i, k, p, n
      line = group%first_line
      if (len_trim(var) == 0) return
      v = to_lower(trim(var))
      n = len(v)
      do i = 1, size(group%lines)
         low = to_lower(uncommented(group%lines(i)))
         p = 0
         do
            k = index(low(p + 1:), v)
            if (k == 0) exit
            k = p + k
            p = k
            if (k > 1) then
               if (is_name_char(low(k - 1:k - 1))) cycle
            end if
            if (next_nonblank(low, k + n) == "=" .or. next_nonblank(low, k + n) == "(" &
                .or. next_nonblank(low, k + n) == "%") then
               line = group%first_line + i - 1
               return
            end if
         end do
      end do
   end function variable_line

   !> A failed read of a group: find the line by reading growing prefixes of the group (each
   !> closed by "/") and name it with its text and the compiler's message.
   subroutine group_read_error(error, nml, ig, msg, reader)
      !> The error.
      type(error_type), allocatable, intent(out) :: error
      !> The scanned file.
      type(namelist_file_type), intent(in) :: nml
      !> Group index.
      integer, intent(in) :: ig
      !> iomsg of the failed read of the whole group.
      character(len=*), intent(in) :: msg
      !> Reads the group's namelist from lines.
      procedure(group_reader) :: reader
      character(len=:), allocatable :: probe(:)
      character(len=512) :: pmsg
      integer :: k, n, stat
      associate (g => nml%groups(ig))
         n = size(g%lines)
         do k = 1, n
            allocate (character(len=max_line) :: probe(k + 1))
            probe(:k) = g%lines(:k)
            probe(k + 1) = "/"
            pmsg = ""
            call reader(probe, stat, pmsg)
            deallocate (probe)
            if (stat /= 0) then
               call fatal_error(error, nml%path//":"//to_string(g%first_line + k - 1)//": &"//g%name//": cannot read '" &
                                //trim(adjustl(g%lines(k)))//"' ("//trim(pmsg)//")", error_code%format)
               return
            end if
         end do
         call fatal_error(error, nml%path//":"//to_string(g%first_line)//": &"//g%name//": "//trim(msg), &
                          error_code%format)
      end associate
   end subroutine group_read_error

   !> Refuse NaN and Inf in a real namelist variable (element I of VAR when it is an array).
   subroutine check_finite(error, nml, ig, gname, var, x)
      !> The error.
      type(error_type), allocatable, intent(out) :: error
      !> The scanned file.
      type(namelist_file_type), intent(in) :: nml
      !> Group index.
      integer, intent(in) :: ig
      !> Group and variable names.
      character(len=*), intent(in) :: gname, var
      !> Values read (all elements).
      real(wp), intent(in) :: x(:)
      integer :: i
      do i = 1, size(x)
         if (.not. ieee_is_finite(x(i))) then
            if (size(x) > 1) then
               call config_error(error, nml, ig, gname, var//"("//to_string(i)//")", &
                                 "is not a finite number (NaN and Inf are refused)")
            else
               call config_error(error, nml, ig, gname, var, "is not a finite number (NaN and Inf are refused)")
            end if
            return
         end if
      end do
   end subroutine check_finite

   ! ---- internals

   subroutine read_text(path, text, error)
      character(len=*), intent(in) :: path
      character(len=:), allocatable, intent(out) :: text
      type(error_type), allocatable, intent(out) :: error
      integer :: unit, stat, sz
      logical :: exists, is_dir
      character(len=512) :: msg
      inquire (file=path, exist=exists)
      if (.not. exists) then
         call fatal_error(error, path//": no such namelist file", error_code%io)
         return
      end if
      inquire (file=path//"/.", exist=is_dir)
      if (is_dir) then
         call fatal_error(error, path//": is a directory, not a namelist file", error_code%io)
         return
      end if
      open (newunit=unit, file=path, access="stream", form="unformatted", action="read", status="old", &
            iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, path//": cannot open ("//trim(msg)//")", error_code%io)
         return
      end if
      inquire (unit=unit, size=sz)
      allocate (character(len=max(0, sz)) :: text)
      stat = 0
      if (sz > 0) read (unit, iostat=stat, iomsg=msg) text
      close (unit)
      if (stat /= 0) call fatal_error(error, path//": cannot read ("//trim(msg)//")", error_code%io)
   end subroutine read_text

   !> Refuse binary content (NUL or other control bytes) and an empty file.
   subroutine check_text(path, text, error)
      character(len=*), intent(in) :: path, text
      type(error_type), allocatable, intent(out) :: error
      integer :: i, c
      if (len(text) >= 4) then
         if (text(2:4) == "HDF") then
            call fatal_error(error, path//": not a namelist file: it is an HDF5 file (a model file?); anm run " &
                             //"needs a namelist text file (docs/namelist.md)", error_code%format)
            return
         end if
      end if
      do i = 1, len(text)
         c = iachar(text(i:i))
         if (c == 9 .or. c == 10 .or. c == 12 .or. c == 13) cycle
         if (c < 32 .or. c == 127) then
            call fatal_error(error, path//": not a namelist file: binary content (byte "//to_string(c) &
                             //" at offset "//to_string(i - 1)//"); anm run needs a namelist text file", &
                             error_code%format)
            return
         end if
      end do
      if (len_trim(text) == 0) then
         call fatal_error(error, path//": empty file: not a namelist file", error_code%format)
      end if
   end subroutine check_text

   !> Split the text into lines and the lines into groups.
   subroutine split_groups(nml, error)
      type(namelist_file_type), intent(inout) :: nml
      type(error_type), allocatable, intent(out) :: error
      character(len=max_line), allocatable :: lines(:)
      type(namelist_group_type), allocatable :: groups(:)
      integer :: ng, il, ic, gstart, gline, gcol, k
      character :: quote, ch
      logical :: in_group
      character(len=:), allocatable :: gname

      il = longest_line(nml%text)
      if (il > 0) then
         call fatal_error(error, nml%path//":"//to_string(il)//": line longer than "//to_string(max_line) &
                          //" characters", error_code%format)
         return
      end if
      call split_lines(nml%text, lines)
      ! at most one group per '&' or '$': no reallocation of the groups while they are built
      allocate (groups(count_groups(nml%text)))
      ng = 0
      in_group = .false.
      quote = " "
      gline = 0
      gcol = 0
      do il = 1, size(lines)
         ic = 0
         do while (ic < len_trim(lines(il)))
            ic = ic + 1
            ch = lines(il)(ic:ic)
            if (quote /= " ") then
               if (ch == quote) quote = " "
               cycle
            end if
            if (ch == "!") exit
            if (ch == "&" .or. ch == "$") then
               gstart = ic
               k = ic
               do while (k < len(lines(il)))
                  if (.not. is_name_char(lines(il)(k + 1:k + 1))) exit
                  k = k + 1
               end do
               gname = to_lower(lines(il)(ic + 1:k))
               ic = k
               if (in_group) then
                  if (gname == "end") then
                     call close_group(il, gstart + 3)
                     cycle
                  end if
                  call fatal_error(error, nml%path//":"//to_string(il)//": namelist group &"//gname &
                                   //" starts before &"//groups(ng)%name//" (line "//to_string(gline) &
                                   //") is closed with '/'", error_code%format)
                  return
               end if
               if (len(gname) == 0 .or. gname == "end") then
                  call fatal_error(error, nml%path//":"//to_string(il)//": '"//lines(il)(gstart:k) &
                                   //"' is not the start of a namelist group (&name)", error_code%format)
                  return
               end if
               in_group = .true.
               gline = il
               gcol = gstart
               ng = ng + 1
               groups(ng)%name = gname
               groups(ng)%first_line = il
               cycle
            end if
            if (in_group) then
               if (ch == "'" .or. ch == '"') then
                  quote = ch
               else if (ch == "/") then
                  call close_group(il, ic)
               end if
            else if (ch /= " " .and. ch /= achar(9) .and. ch /= achar(12)) then
               call fatal_error(error, nml%path//":"//to_string(il)//": text outside a namelist group: '" &
                                //trim(adjustl(lines(il)(ic:)))//"' (a group starts with &name and ends with /; " &
                                //"comments start with !)", error_code%format)
               return
            end if
         end do
      end do
      if (in_group) then
         call fatal_error(error, nml%path//":"//to_string(gline)//": namelist group &"//groups(ng)%name &
                          //" is not closed with '/'", error_code%format)
         return
      end if
      if (ng == 0) then
         call fatal_error(error, nml%path//": no namelist group (&name ... /) in the file: not a namelist file", &
                          error_code%format)
         return
      end if
      allocate (nml%groups(ng))
      do k = 1, ng
         nml%groups(k)%name = groups(k)%name
         nml%groups(k)%first_line = groups(k)%first_line
         nml%groups(k)%last_line = groups(k)%last_line
         call move_alloc(groups(k)%lines, nml%groups(k)%lines)
      end do

   contains

      subroutine close_group(iline, icol)
         integer, intent(in) :: iline, icol
         integer :: j
         in_group = .false.
         groups(ng)%last_line = iline
         allocate (groups(ng)%lines(iline - gline + 1))
         do j = gline, iline
            groups(ng)%lines(j - gline + 1) = lines(j)
         end do
         groups(ng)%lines(1)(:gcol - 1) = ""
         groups(ng)%lines(iline - gline + 1)(icol + 1:) = ""
      end subroutine close_group
   end subroutine split_groups

   !> First line longer than max_line (trailing blanks and CR excluded), 0 if none.
   pure integer function longest_line(text) result(line)
      character(len=*), intent(in) :: text
      integer :: i, start, nline
      line = 0
      start = 1
      nline = 1
      do i = 1, len(text) + 1
         if (i > len(text)) then
            if (len_trim(text(start:)) > max_line) line = nline
         else if (text(i:i) == achar(10)) then
            if (len_trim(text(start:i - 1)) > max_line + 1) line = nline
            nline = nline + 1
            start = i + 1
         end if
         if (line > 0) return
      end do
   end function longest_line

   !> Upper bound of the number of groups: the number of '&' and '$'.
   pure integer function count_groups(text) result(n)
      character(len=*), intent(in) :: text
      integer :: i
      n = 0
      do i = 1, len(text)
         if (text(i:i) == "&" .or. text(i:i) == "$") n = n + 1
      end do
   end function count_groups

   !> Lines of a text (LF or CR LF line ends; tabs become blanks).
   pure subroutine split_lines(text, lines)
      character(len=*), intent(in) :: text
      character(len=max_line), allocatable, intent(out) :: lines(:)
      integer :: n, i, start, k
      n = 1
      do i = 1, len(text)
         if (text(i:i) == achar(10)) n = n + 1
      end do
      allocate (lines(n))
      lines = ""
      k = 1
      start = 1
      do i = 1, len(text) + 1
         if (i > len(text)) then
            lines(k) = text(start:)
         else if (text(i:i) == achar(10)) then
            lines(k) = text(start:i - 1)
            k = k + 1
            start = i + 1
         end if
      end do
      do k = 1, n
         do i = 1, max_line
            if (lines(k)(i:i) == achar(13) .or. lines(k)(i:i) == achar(9) .or. lines(k)(i:i) == achar(12)) &
               lines(k)(i:i) = " "
         end do
      end do
   end subroutine split_lines

   !> A line without its comment (a "!" outside quotes).
   pure function uncommented(line) result(s)
      character(len=*), intent(in) :: line
      character(len=:), allocatable :: s
      character :: quote
      integer :: i
      quote = " "
      s = line
      do i = 1, len(line)
         if (quote /= " ") then
            if (line(i:i) == quote) quote = " "
            s(i:i) = " "
         else if (line(i:i) == "'" .or. line(i:i) == '"') then
            quote = line(i:i)
         else if (line(i:i) == "!") then
            s = line(:i - 1)
            return
         end if
      end do
   end function uncommented

   pure logical function is_name_char(c)
      character, intent(in) :: c
      is_name_char = (c >= "a" .and. c <= "z") .or. (c >= "A" .and. c <= "Z") .or. (c >= "0" .and. c <= "9") &
                     .or. c == "_"
   end function is_name_char

   pure function next_nonblank(s, after) result(c)
      character(len=*), intent(in) :: s
      integer, intent(in) :: after
      character :: c
      integer :: i
      c = " "
      do i = after + 1, len(s)
         if (s(i:i) /= " ") then
            c = s(i:i)
            return
         end if
      end do
   end function next_nonblank

   pure function join(names) result(s)
      character(len=*), intent(in) :: names(:)
      character(len=:), allocatable :: s
      integer :: i
      s = ""
      do i = 1, size(names)
         if (i > 1) s = s//", "
         s = s//"&"//trim(names(i))
      end do
   end function join
end module anm_config_namelist
