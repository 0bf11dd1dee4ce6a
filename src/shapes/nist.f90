!> Reader and writer of NIST "anm" spherical-harmonic coefficient files.
!>
!> Format (see ../shared/shapes/README.md): one line per coefficient, `n m Re(a_nm) Im(a_nm)`,
!> n = 0, 1, ..., nmax and for each n, m = n, n-1, ..., -n. Any complete set of degrees up to 200
!> is accepted (nmax = 30 in NIST's files; from degree 100 on fixed columns may run together,
!> " 100-100", and are split). Malformed files are refused with a message naming the
!> file and the line.
!>
!> Usage:
!>     call read_nist_shape("MA111-7-coarse-anm-00002.dat", shape, error)
!>     call write_nist_shape("out.dat", shape, error)
module anm_shapes_nist
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion, sh_to_complex
   use anm_core_output, only: output_set_type, check_complete
   use anm_core_text, only: printable
   implicit none
   private

   public :: read_nist_shape, write_nist_shape

contains

   !> Read a coefficient file into an expansion. Errors name the file and line: unreadable file,
   !> empty file, non-numeric field, wrong field count, (n, m) out of sequence (a missing or extra
   !> coefficient), a file that ends inside a degree (truncated).
   subroutine read_nist_shape(path, shape, error, nmax_read)
      !> File to read.
      character(len=*), intent(in) :: path
      !> Expansion of all degrees in the file.
      type(sh_expansion_type), intent(out) :: shape
      !> Error with file and line.
      type(error_type), allocatable, intent(out) :: error
      !> Highest degree found in the file.
      integer, intent(out), optional :: nmax_read
      integer, parameter :: ncap = 200
      complex(wp), allocatable :: c(:, :)
      character(len=512) :: line, msg
      integer :: unit, stat, lineno, n, m, nexp, mexp, nmax
      real(wp) :: re, im, rest

      open (newunit=unit, file=path, status="old", action="read", iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, trim(path)//": cannot open shape file ("//trim(msg)//")", error_code%io)
         return
      end if
      allocate (c(0:ncap, -ncap:ncap))
      c = (0.0_wp, 0.0_wp)
      lineno = 0
      nexp = 0
      mexp = 0
      nmax = -1
      do
         read (unit, '(a)', iostat=stat) line
         if (is_iostat_end(stat)) exit
         lineno = lineno + 1
         if (stat /= 0) then
            call fail("cannot read line")
            return
         end if
         line = split_glued(line)
         if (len_trim(line) == 0) then
            ! blank lines are allowed only at the end of the file
            call skip_trailing_blank()
            if (allocated(error)) return
            exit
         end if
         if (count_fields(line) /= 4) then
            call fail("expected 4 fields 'n m Re(a_nm) Im(a_nm)', found " &
                      //to_string(count_fields(line))//": '"//printable(trim(line))//"'")
            return
         end if
         read (line, *, iostat=stat) n, m, re, im
         if (stat /= 0) then
            call fail("non-numeric field in '"//printable(trim(line))//"'")
            return
         end if
         if (re /= re .or. im /= im .or. abs(re) > huge(re) .or. abs(im) > huge(im)) then
            call fail("coefficient is not a finite number: '"//printable(trim(line))//"'")
            return
         end if
         if (n /= nexp .or. m /= mexp) then
            call fail("expected coefficient n = "//to_string(nexp)//", m = "//to_string(mexp) &
                      //" but found n = "//to_string(n)//", m = "//to_string(m) &
                      //" (missing or misplaced coefficient)")
            return
         end if
         if (n > ncap) then
            call fail("degree "//to_string(n)//" exceeds the supported maximum "//to_string(ncap))
            return
         end if
         c(n, m) = cmplx(re, im, wp)
         ! next expected (n, m): m runs n..-n
         if (m == -n) then
            nmax = n
            nexp = n + 1
            mexp = n + 1
         else
            mexp = m - 1
         end if
      end do
      close (unit)
      if (lineno == 0) then
         call fatal_error(error, trim(path)//": empty shape file (no coefficient lines)", error_code%format)
         return
      end if
      if (mexp /= nexp) then
         call fatal_error(error, trim(path)//":"//to_string(lineno)//": file ends inside degree " &
                          //to_string(nexp)//" (truncated file: expected m down to "//to_string(-nexp) &
                          //", last m read "//to_string(mexp + 1)//")", error_code%format)
         return
      end if
      if (abs(aimag(c(0, 0))) > 0.0_wp .or. .not. (real(c(0, 0), wp) > 0.0_wp)) then
         call fatal_error(error, trim(path)//":1: a_00 must be real and positive (mean radius), found " &
                          //to_string(real(c(0, 0), wp))//" + "//to_string(aimag(c(0, 0)))//" i", &
                          error_code%value)
         return
      end if
      ! a degenerate shape: a mean radius too small to give a volume, or negligible against the
      ! other coefficients (the surface cannot be star-shaped)
      rest = sqrt(max(0.0_wp, sum(abs(c(0:nmax, -nmax:nmax))**2) - real(c(0, 0), wp)**2))
      if (real(c(0, 0), wp) < 1.0e-50_wp .or. real(c(0, 0), wp) < 1.0e-6_wp * rest) then
         call fatal_error(error, trim(path)//":1: degenerate shape: a_00 = "//to_string(real(c(0, 0), wp)) &
                          //" is too small (against the other coefficients, norm "//to_string(rest) &
                          //") to describe a particle", error_code%value)
         return
      end if
      call new_sh_expansion(shape, c(0:nmax, -nmax:nmax), nmax)
      if (present(nmax_read)) nmax_read = nmax
   contains
      subroutine fail(what)
         character(len=*), intent(in) :: what
         call fatal_error(error, trim(path)//":"//to_string(lineno)//": "//what, error_code%format)
         close (unit)
      end subroutine fail

      subroutine skip_trailing_blank()
         do
            read (unit, '(a)', iostat=stat) line
            if (is_iostat_end(stat)) exit
            lineno = lineno + 1
            if (len_trim(line) /= 0) then
               call fail("blank line inside the coefficient list")
               return
            end if
         end do
      end subroutine skip_trailing_blank
   end subroutine read_nist_shape

   !> The line with a blank inserted before a sign that follows a digit (fixed `%4d%4d` columns run
   !> together from degree 100 on: " 100-100" is n = 100, m = -100); exponents (1.0e-05) are kept.
   pure function split_glued(line) result(out)
      character(len=*), intent(in) :: line
      character(len=len(line)) :: out
      integer :: i, k
      out = ""
      k = 0
      do i = 1, len_trim(line)
         if (i > 1 .and. (line(i:i) == "-" .or. line(i:i) == "+")) then
            if (index("0123456789.", line(i - 1:i - 1)) > 0 .and. k < len(out)) then
               k = k + 1
               out(k:k) = " "
            end if
         end if
         if (k >= len(out)) exit
         k = k + 1
         out(k:k) = line(i:i)
      end do
   end function split_glued

   !> Number of blank-separated fields in a line.
   pure function count_fields(line) result(nf)
      character(len=*), intent(in) :: line
      integer :: nf, i
      logical :: inword
      nf = 0
      inword = .false.
      do i = 1, len_trim(line)
         if (line(i:i) == " " .or. line(i:i) == achar(9) .or. line(i:i) == ",") then
            inword = .false.
         else if (.not. inword) then
            inword = .true.
            nf = nf + 1
         end if
      end do
   end function count_fields

   !> Write an expansion in the NIST layout (`%4d%4d%20.10f%20.10f`, conjugate-symmetric m < 0;
   !> from degree 100 on the integer columns are 5 wide so that they stay separated), safely: to a
   !> temporary name in the same folder, every write and the close checked, then renamed.
   subroutine write_nist_shape(path, shape, error)
      !> File to write (replaced if it exists).
      character(len=*), intent(in) :: path
      !> Expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> Error when the file cannot be written.
      type(error_type), allocatable, intent(out) :: error
      complex(wp), allocatable :: c(:, :)
      integer :: unit, stat, n, m, s2
      character(len=512) :: msg
      character(len=:), allocatable :: tmp, fmt
      type(output_set_type) :: set

      allocate (c(0:shape%nmax, -shape%nmax:shape%nmax))
      c(:, :) = sh_to_complex(shape)
      fmt = '(2i4,2f20.10)'
      if (shape%nmax >= 100) fmt = '(2i5,2f20.10)'
      call set%add(path, tmp)
      open (newunit=unit, file=tmp, access="stream", form="formatted", status="replace", action="write", &
            iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, trim(path)//": cannot write shape file ("//trim(msg)//")", error_code%io)
         call set%discard()
         return
      end if
      do n = 0, shape%nmax
         do m = n, -n, -1
            write (unit, fmt, iostat=stat, iomsg=msg) n, m, real(c(n, m), wp), aimag(c(n, m))
            if (stat /= 0) exit
         end do
         if (stat /= 0) exit
      end do
      if (stat == 0) then
         call check_complete(unit, tmp, trim(path), error)
         if (allocated(error)) then
            close (unit, iostat=s2)
            call set%discard()
            return
         end if
         close (unit, iostat=stat, iomsg=msg)
      else
         close (unit, iostat=s2)
      end if
      if (stat /= 0) then
         call fatal_error(error, trim(path)//": write failed ("//trim(msg)//")", error_code%io)
         call set%discard()
         return
      end if
      call set%commit(error)
   end subroutine write_nist_shape
end module anm_shapes_nist
