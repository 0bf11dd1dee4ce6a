!> On-disk cache of per-shape kind data (geometry, contact bodies, shell layers) between runs.
!>
!> An entry is one file `<hash>.kind` in the cache folder: a header (magic, key length, payload
!> length, payload hash), the key and the payload. The key holds everything the payload depends
!> on: the caller's inputs (coefficients, order, thicknesses, build parameters) and the code
!> version (the cache format version, the compiler's version and options, and a hash of the running
!> executable, so that any rebuild of the program starts a fresh set of entries). The file name is
!> a hash of the key; the key itself is stored and compared byte for byte, and the payload's hash
!> is checked, so a corrupt, truncated or foreign file is detected (`rejected`) and the caller
!> rebuilds and overwrites it. Entries are written with the project's safe writes (a temporary in
!> the same folder, checked, fsync'd and renamed: anm_core_output), so concurrent runs sharing a
!> folder never read a partial entry.
!>
!> The cache is not thread-safe: one thread reads and writes entries (the kinds are built in
!> parallel between the reads and the writes).
!>
!> Usage:
!>     call new_kind_cache(cache, dir)          ! dir = '' or 'off': no cache
!>     call key_start(cache, "base", w)         ! then w%put(...) the inputs
!>     call cache%load(w%bytes(), r, hit)       ! r%get(...) the payload, check r%done()
!>     call cache%store(w%bytes(), payload%bytes())
module anm_parking_kind_cache
   use, intrinsic :: iso_c_binding, only: c_char, c_int64_t, c_null_char
   use, intrinsic :: iso_fortran_env, only: int8, int64, compiler_version, compiler_options
   use anm_core_kinds, only: wp, sp
   use anm_core_error, only: error_type
   use anm_core_filesystem, only: join_path, make_directory
   use anm_core_output, only: output_set_type, check_complete, remove_stale_temps
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real
   use anm_contact_body, only: contact_body_type, leaf_level, stored_level, node_size
   implicit none
   private

   public :: kind_cache_type, new_kind_cache, byte_writer_type, byte_reader_type, key_start, cache_format_version, &
      & put_body, get_body, put_expansion, get_expansion, fnv1a

   !> Version of the entry layout and of what the payloads hold; bump when they change.
   integer, parameter :: cache_format_version = 3
   !> First bytes of every entry.
   character(len=8), parameter :: magic = "ANMKIND1"
   !> Header: magic, key length, payload length, payload hash.
   integer, parameter :: header_bytes = 32

   interface
      function c_fnv1a(p, n, h) bind(c, name="anm_fnv1a") result(r)
         import :: c_int64_t, int8
         integer(int8), intent(in) :: p(*)
         integer(c_int64_t), value, intent(in) :: n, h
         integer(c_int64_t) :: r
      end function c_fnv1a
      function c_fnv1a_file(path) bind(c, name="anm_fnv1a_file") result(r)
         import :: c_char, c_int64_t
         character(kind=c_char), intent(in) :: path(*)
         integer(c_int64_t) :: r
      end function c_fnv1a_file
   end interface

   !> A growing byte buffer (keys and payloads).
   type :: byte_writer_type
      !> Storage (the first n bytes used).
      integer(int8), allocatable :: b(:)
      !> Bytes written.
      integer(int64) :: n = 0
   contains
      procedure, private :: put_int, put_long, put_ints, put_real, put_reals, put_reals2, put_singles, put_text
      !> Append a value or an array (arrays without their shape: put the shape first when it varies).
      generic :: put => put_int, put_long, put_ints, put_real, put_reals, put_reals2, put_singles, put_text
      !> The bytes written.
      procedure :: bytes
   end type byte_writer_type

   !> Reading a payload back; `bad` is set (and zeros returned) on reading past its end.
   type :: byte_reader_type
      !> The payload.
      integer(int8), allocatable :: b(:)
      !> Bytes read so far.
      integer(int64) :: pos = 0
      !> Set when a read went past the end (or the payload was malformed).
      logical :: bad = .false.
   contains
      procedure, private :: get_int, get_ints, get_real, get_reals, get_singles
      !> Read a value or fill an (allocated) array.
      generic :: get => get_int, get_ints, get_real, get_reals, get_singles
      !> True when the whole payload was read without error.
      procedure :: done
   end type byte_reader_type

   !> The cache of a run: its folder (none: off) and what it did.
   type :: kind_cache_type
      !> Whether the cache is used.
      logical :: on = .false.
      !> Folder.
      character(len=:), allocatable :: dir
      !> Code version bytes (part of every key).
      integer(int8), allocatable :: code(:)
      !> Entries read, looked up but missing, rejected (corrupt or foreign), written, not written.
      integer :: hits = 0, misses = 0, rejected = 0, written = 0, write_failed = 0
      !> Why the cache is off or the last write failed (empty: no problem).
      character(len=:), allocatable :: problem
   contains
      !> Look up an entry by its key.
      procedure :: load
      !> Write an entry (errors are counted, not returned: the cache never fails a run).
      procedure :: store
   end type kind_cache_type

contains

   !> A cache in folder `dir` (created if missing); '' or 'off' (any case): no cache.
   subroutine new_kind_cache(cache, dir)
      !> Cache.
      type(kind_cache_type), intent(out) :: cache
      !> Folder.
      character(len=*), intent(in) :: dir
      type(error_type), allocatable :: error
      type(byte_writer_type) :: w
      integer(c_int64_t) :: exe
      cache%problem = ""
      if (len_trim(dir) == 0) return
      if (lower(trim(dir)) == "off") return
      call make_directory(trim(dir), error)
      if (allocated(error)) then
         cache%problem = error%message
         return
      end if
      exe = c_fnv1a_file("/proc/self/exe"//c_null_char)
      if (exe == 0) then
         cache%problem = "cannot read /proc/self/exe (needed for the cache's code version)"
         return
      end if
      call w%put(cache_format_version)
      call w%put(int(exe, int64))
      call w%put(compiler_version())
      call w%put(compiler_options())
      call w%put([storage_size(1.0_wp), storage_size(1.0_sp), leaf_level, stored_level, node_size])
      cache%code = w%bytes()
      ! temporaries of runs killed while writing an entry
      call remove_stale_temps(trim(dir))
      cache%dir = trim(dir)
      cache%on = .true.
   end subroutine new_kind_cache

   !> Start a key: the code version and the kind of entry (`what`); append the inputs to it.
   subroutine key_start(cache, what, w)
      !> Cache.
      type(kind_cache_type), intent(in) :: cache
      !> Kind of entry.
      character(len=*), intent(in) :: what
      !> Key being built.
      type(byte_writer_type), intent(out) :: w
      if (allocated(cache%code)) then
         call w%put(int(size(cache%code), int64))
         call put_raw(w, cache%code)
      end if
      call w%put(what)
   end subroutine key_start

   !> 64-bit FNV-1a-style hash of a byte string (8 bytes a step: kind_cache.c).
   function fnv1a(b) result(h)
      !> Bytes.
      integer(int8), intent(in) :: b(:)
      integer(int64) :: h
      h = c_fnv1a(b, int(size(b), c_int64_t), 0_c_int64_t)
   end function fnv1a

   !> File of the entry with key `key`.
   function entry_path(cache, key) result(path)
      type(kind_cache_type), intent(in) :: cache
      integer(int8), intent(in) :: key(:)
      character(len=:), allocatable :: path
      character(len=16) :: hex
      write (hex, '(z16.16)') fnv1a(key)
      path = join_path(cache%dir, lower(hex)//".kind")
   end function entry_path

   !> Look up the entry of `key`: `hit` with its payload in `r`, else a miss (no file) or a
   !> rejection (a file that is not a complete entry of this key: counted in `rejected`).
   subroutine load(self, key, r, hit)
      !> Cache.
      class(kind_cache_type), intent(inout) :: self
      !> Key.
      integer(int8), intent(in) :: key(:)
      !> Payload (on a hit).
      type(byte_reader_type), intent(out) :: r
      !> Whether the entry was found and is sound.
      logical, intent(out) :: hit
      character(len=:), allocatable :: path
      character(len=8) :: mg
      integer(int64) :: nkey, npay, hpay, fsize
      integer(int8), allocatable :: k(:)
      integer :: unit, stat
      logical :: exists
      hit = .false.
      if (.not. self%on) return
      path = entry_path(self, key)
      inquire (file=path, exist=exists)
      if (.not. exists) then
         self%misses = self%misses + 1
         return
      end if
      open (newunit=unit, file=path, access="stream", form="unformatted", status="old", action="read", iostat=stat)
      if (stat /= 0) then
         self%rejected = self%rejected + 1
         return
      end if
      inquire (unit=unit, size=fsize)
      read (unit, iostat=stat) mg, nkey, npay, hpay
      if (stat == 0 .and. mg == magic .and. nkey == size(key) .and. npay >= 0 .and. &
          fsize == header_bytes + nkey + npay) then
         allocate (k(nkey), r%b(npay))
         read (unit, iostat=stat) k, r%b
         if (stat == 0) hit = all(k == key)
         if (hit) hit = fnv1a(r%b) == hpay
      end if
      close (unit)
      if (hit) then
         self%hits = self%hits + 1
      else
         self%rejected = self%rejected + 1
         if (allocated(r%b)) deallocate (r%b)
      end if
   end subroutine load

   !> Write the entry (key, payload), replacing any earlier file of that key.
   subroutine store(self, key, payload)
      !> Cache.
      class(kind_cache_type), intent(inout) :: self
      !> Key and payload.
      integer(int8), intent(in) :: key(:), payload(:)
      type(output_set_type) :: set
      type(error_type), allocatable :: error
      character(len=:), allocatable :: path, tmp, why
      character(len=512) :: msg
      integer :: unit, stat
      if (.not. self%on) return
      why = ""
      path = entry_path(self, key)
      call set%add(path, tmp)
      open (newunit=unit, file=tmp, access="stream", form="unformatted", status="replace", action="write", &
            iostat=stat, iomsg=msg)
      if (stat /= 0) then
         self%write_failed = self%write_failed + 1
         self%problem = path//": cannot open for writing ("//trim(msg)//")"
         call set%discard()
         return
      end if
      write (unit, iostat=stat, iomsg=msg) magic, int(size(key), int64), int(size(payload), int64), fnv1a(payload), &
         key, payload
      if (stat /= 0) then
         why = path//": write failed ("//trim(msg)//")"
      else
         call check_complete(unit, tmp, path, error)
         if (allocated(error)) why = error%message
      end if
      close (unit, iostat=stat)
      if (stat /= 0 .and. len(why) == 0) why = path//": error closing the file"
      if (len(why) == 0) then
         call set%commit(error)
         if (allocated(error)) why = error%message
      else
         call set%discard()
      end if
      if (len(why) > 0) then
         self%write_failed = self%write_failed + 1
         self%problem = why
      else
         self%written = self%written + 1
      end if
   end subroutine store

   !> A contact body's data except its shape (the caller knows it): the certified scalars and,
   !> when `full`, the patch arrays (not the support table: the kinds build it when their use
   !> pays for it, anm_parking_kinds).
   subroutine put_body(w, body, full)
      !> Buffer.
      type(byte_writer_type), intent(inout) :: w
      !> Body.
      type(contact_body_type), intent(in) :: body
      !> Whether the patch arrays are written.
      logical, intent(in) :: full
      call w%put([body%nmax, body%next])
      call w%put([body%r_max, body%r_min, body%lipschitz, body%curvature, body%third, body%box_lo, body%box_hi, &
                  body%ext_lo, body%ext_hi])
      call w%put([body%off, body%doff, body%roff, body%coff])
      call w%put(merge(1, 0, full))
      if (.not. full) return
      call w%put(size(body%cosa))
      call w%put(size(body%dlo))
      call w%put(size(body%row_ct))
      call w%put(size(body%col_cp))
      call w%put(body%dir)
      call w%put(body%cosa)
      call w%put(body%sina)
      call w%put(body%rlo)
      call w%put(body%rhi)
      call w%put(body%ball)
      call w%put(body%brad)
      call w%put(body%dlo)
      call w%put(body%dhi)
      call w%put(body%row_ct)
      call w%put(body%row_st)
      call w%put(body%row_cosa)
      call w%put(body%row_sina)
      call w%put(body%col_cp)
      call w%put(body%col_sp)
      call w%put(body%node)
   end subroutine put_body

   !> Read what put_body wrote (the shape is set by the caller); r%bad on a malformed payload.
   subroutine get_body(r, body)
      !> Payload.
      type(byte_reader_type), intent(inout) :: r
      !> Body (its shape untouched).
      type(contact_body_type), intent(inout) :: body
      integer :: i2(2), offs(size(body%off) + size(body%doff) + size(body%roff) + size(body%coff)), full, np, nd, nr, nc
      real(wp) :: x(17)
      integer :: a, b
      call r%get(i2)
      call r%get(x)
      call r%get(offs)
      call r%get(full)
      body%nmax = i2(1)
      body%next = i2(2)
      body%r_max = x(1)
      body%r_min = x(2)
      body%lipschitz = x(3)
      body%curvature = x(4)
      body%third = x(5)
      body%box_lo = x(6:8)
      body%box_hi = x(9:11)
      body%ext_lo = x(12:14)
      body%ext_hi = x(15:17)
      a = 1
      b = size(body%off)
      body%off = offs(a:b)
      a = b + 1
      b = b + size(body%doff)
      body%doff = offs(a:b)
      a = b + 1
      b = b + size(body%roff)
      body%roff = offs(a:b)
      a = b + 1
      b = b + size(body%coff)
      body%coff = offs(a:b)
      if (full /= 1 .or. r%bad) return
      call r%get(np)
      call r%get(nd)
      call r%get(nr)
      call r%get(nc)
      ! sizes that do not fit the rest of the payload make it malformed (never allocated)
      if (r%bad .or. min(np, nd, nr, nc) < 0 .or. &
          8_int64 * (int(np, int64) * (11 + node_size) + 4 * nr + 2 * nc) + 8_int64 * nd > size(r%b) - r%pos) then
         r%bad = .true.
         return
      end if
      allocate (body%dir(3, np), body%cosa(np), body%sina(np), body%rlo(np), body%rhi(np), body%ball(3, np), &
                body%brad(np), body%dlo(nd), body%dhi(nd), body%row_ct(nr), body%row_st(nr), body%row_cosa(nr), &
                body%row_sina(nr), body%col_cp(nc), body%col_sp(nc), body%node(node_size, np))
      call get_reals2(r, body%dir)
      call r%get(body%cosa)
      call r%get(body%sina)
      call r%get(body%rlo)
      call r%get(body%rhi)
      call get_reals2(r, body%ball)
      call r%get(body%brad)
      call r%get(body%dlo)
      call r%get(body%dhi)
      call r%get(body%row_ct)
      call r%get(body%row_st)
      call r%get(body%row_cosa)
      call r%get(body%row_sina)
      call r%get(body%col_cp)
      call r%get(body%col_sp)
      call get_reals2(r, body%node)
   end subroutine get_body

   !> An expansion's degree and coefficients.
   subroutine put_expansion(w, e)
      !> Buffer.
      type(byte_writer_type), intent(inout) :: w
      !> Expansion.
      type(sh_expansion_type), intent(in) :: e
      call w%put(e%nmax)
      call w%put(e%a)
      call w%put(e%b)
   end subroutine put_expansion

   !> Read what put_expansion wrote (the expansion rebuilt from its coefficients).
   subroutine get_expansion(r, e)
      !> Payload.
      type(byte_reader_type), intent(inout) :: r
      !> Expansion.
      type(sh_expansion_type), intent(out) :: e
      real(wp), allocatable :: a(:, :), b(:, :)
      integer :: n
      call r%get(n)
      if (r%bad .or. n < 0 .or. 16_int64 * (n + 1)**2 > size(r%b) - r%pos) then
         r%bad = .true.
         return
      end if
      allocate (a(0:n, 0:n), b(0:n, 0:n))
      call get_reals2(r, a)
      call get_reals2(r, b)
      call new_sh_expansion_real(e, a, b)
   end subroutine get_expansion

   ! ----- byte buffers

   subroutine reserve(w, m)
      type(byte_writer_type), intent(inout) :: w
      integer(int64), intent(in) :: m
      integer(int8), allocatable :: t(:)
      if (.not. allocated(w%b)) allocate (w%b(max(256_int64, m)))
      if (w%n + m <= size(w%b, kind=int64)) return
      allocate (t(max(2 * size(w%b, kind=int64), w%n + m)))
      t(:w%n) = w%b(:w%n)
      call move_alloc(t, w%b)
   end subroutine reserve

   subroutine put_raw(w, x)
      type(byte_writer_type), intent(inout) :: w
      integer(int8), intent(in) :: x(:)
      call reserve(w, size(x, kind=int64))
      w%b(w%n + 1:w%n + size(x)) = x
      w%n = w%n + size(x)
   end subroutine put_raw

   subroutine put_int(w, x)
      class(byte_writer_type), intent(inout) :: w
      integer, intent(in) :: x
      call put_raw(w, transfer(x, [0_int8]))
   end subroutine put_int

   subroutine put_long(w, x)
      class(byte_writer_type), intent(inout) :: w
      integer(int64), intent(in) :: x
      call put_raw(w, transfer(x, [0_int8]))
   end subroutine put_long

   subroutine put_ints(w, x)
      class(byte_writer_type), intent(inout) :: w
      integer, intent(in) :: x(:)
      call put_raw(w, transfer(x, [0_int8]))
   end subroutine put_ints

   subroutine put_real(w, x)
      class(byte_writer_type), intent(inout) :: w
      real(wp), intent(in) :: x
      call put_raw(w, transfer(x, [0_int8]))
   end subroutine put_real

   subroutine put_reals(w, x)
      class(byte_writer_type), intent(inout) :: w
      real(wp), intent(in) :: x(:)
      call put_raw(w, transfer(x, [0_int8]))
   end subroutine put_reals

   subroutine put_reals2(w, x)
      class(byte_writer_type), intent(inout) :: w
      real(wp), intent(in) :: x(:, :)
      call put_raw(w, transfer(x, [0_int8]))
   end subroutine put_reals2

   subroutine put_singles(w, x)
      class(byte_writer_type), intent(inout) :: w
      real(sp), intent(in) :: x(:)
      call put_raw(w, transfer(x, [0_int8]))
   end subroutine put_singles

   subroutine put_text(w, x)
      class(byte_writer_type), intent(inout) :: w
      character(len=*), intent(in) :: x
      call put_raw(w, transfer(len(x, kind=int64), [0_int8]))
      if (len(x) > 0) call put_raw(w, transfer(x, [0_int8], len(x)))
   end subroutine put_text

   function bytes(w) result(b)
      class(byte_writer_type), intent(in) :: w
      integer(int8), allocatable :: b(:)
      if (allocated(w%b)) then
         b = w%b(:w%n)
      else
         allocate (b(0))
      end if
   end function bytes

   !> The next m bytes (or .false. and r%bad when fewer are left).
   logical function take(r, m, lo, hi)
      type(byte_reader_type), intent(inout) :: r
      integer(int64), intent(in) :: m
      integer(int64), intent(out) :: lo, hi
      take = .false.
      lo = r%pos + 1
      hi = r%pos + m
      if (r%bad .or. .not. allocated(r%b)) then
         r%bad = .true.
         return
      end if
      if (hi > size(r%b, kind=int64)) then
         r%bad = .true.
         return
      end if
      r%pos = hi
      take = .true.
   end function take

   subroutine get_int(r, x)
      class(byte_reader_type), intent(inout) :: r
      integer, intent(out) :: x
      integer(int64) :: lo, hi
      x = 0
      if (take(r, int(storage_size(x) / 8, int64), lo, hi)) x = transfer(r%b(lo:hi), x)
   end subroutine get_int

   subroutine get_ints(r, x)
      class(byte_reader_type), intent(inout) :: r
      integer, intent(out) :: x(:)
      integer(int64) :: lo, hi
      x = 0
      if (take(r, int(size(x), int64) * (storage_size(x) / 8), lo, hi)) x = transfer(r%b(lo:hi), x, size(x))
   end subroutine get_ints

   subroutine get_real(r, x)
      class(byte_reader_type), intent(inout) :: r
      real(wp), intent(out) :: x
      integer(int64) :: lo, hi
      x = 0.0_wp
      if (take(r, int(storage_size(x) / 8, int64), lo, hi)) x = transfer(r%b(lo:hi), x)
   end subroutine get_real

   subroutine get_reals(r, x)
      class(byte_reader_type), intent(inout) :: r
      real(wp), intent(out) :: x(:)
      integer(int64) :: lo, hi
      x = 0.0_wp
      if (take(r, int(size(x), int64) * (storage_size(x) / 8), lo, hi)) x = transfer(r%b(lo:hi), x, size(x))
   end subroutine get_reals

   subroutine get_reals2(r, x)
      type(byte_reader_type), intent(inout) :: r
      real(wp), intent(out) :: x(:, :)
      integer(int64) :: lo, hi
      x = 0.0_wp
      if (take(r, int(size(x), int64) * (storage_size(x) / 8), lo, hi)) &
         x = reshape(transfer(r%b(lo:hi), x, size(x)), shape(x))
   end subroutine get_reals2

   subroutine get_singles(r, x)
      class(byte_reader_type), intent(inout) :: r
      real(sp), intent(out) :: x(:)
      integer(int64) :: lo, hi
      x = 0.0_sp
      if (take(r, int(size(x), int64) * (storage_size(x) / 8), lo, hi)) x = transfer(r%b(lo:hi), x, size(x))
   end subroutine get_singles

   logical function done(r)
      class(byte_reader_type), intent(in) :: r
      done = .false.
      if (.not. allocated(r%b)) return
      done = .not. r%bad .and. r%pos == size(r%b, kind=int64)
   end function done

   pure function lower(s) result(t)
      character(len=*), intent(in) :: s
      character(len=len(s)) :: t
      integer :: i
      t = s
      do i = 1, len(s)
         if (s(i:i) >= "A" .and. s(i:i) <= "Z") t(i:i) = achar(iachar(s(i:i)) + 32)
      end do
   end function lower
end module anm_parking_kind_cache
