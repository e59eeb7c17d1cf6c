; Sieve of Eratosthenes on the 8-bit processor (paper Sec. "Demonstration of a mechanical processor").
; Primality array at 128..159: mem[128+n] != 0 <=> n is composite, for n = 0..31.  The program marks
; the multiples 2p, 3p, ... <= 31 of every p = 2, 3, 4, 5 (p*p < 32), then halts.  It does not test
; whether p is already marked (the paper skips composite p; here p = 4 re-marks multiples of 2).
; 0 and 1 are left 0: they are neither prime nor composite and the sieve never touches them.
; Marks hold the step p that wrote them.  43 bytes; addresses 43..127 are unused.
; It reads no register before writing it, so it does not depend on their power-up values.
;
; Registers in the marking loop: A = address to mark, C = mark (the loop), D = p.

        .equ ARRAY 128
        .equ LAST 159               ; ARRAY + 31
        .result primes zeros ARRAY+2 30 2   ; what it computes: the numbers 2..31 left unmarked

        LDNX_AB cont                ; C = cont: the jump at 6 falls through to 7
        SWAP_AC
        LDNX_AB 2
        SWAP_AB                     ; B = 2
halt:   JMP_C                       ; at address 6; a jump here with C = 6 stops the processor
cont:   SWAP_BD                     ; D = p = 2
        LDNX_AB mark
        SWAP_AC                     ; C = mark
        LDNX_AB ARRAY+4             ; A = first multiple of 2 to mark

mark:   SWAP_BD                     ; B = p
        APLUSB_TO_D                 ; D = next address = A + p
        SWAP_AB                     ; A = p, B = address
        SAVE_AB                     ; mem[address] = p (non-zero: composite)
        SWAP_AB
        LDNX_AB LAST
        SWAP_BD                     ; B = next address, D = p
        SWAP_AB                     ; A = next address, B = LAST
        SKPNX_A_GRT_B               ; past the array: leave the loop
        JMP_C

        ; next p: p' = p + 1; stop when p' = 6 (6 * 6 > 31); first address ARRAY + 2p'
        LDNX_AB 1
        SWAP_BD                     ; B = p
        APLUSB_TO_D                 ; D = p'
        LDNX_AB ARRAY
        SWAP_BD                     ; B = p', D = p
        APLUSB_TO_D                 ; D = ARRAY + p'
        SWAP_AB                     ; A = p', B = ARRAY
        SWAP_BD                     ; B = ARRAY + p', D = ARRAY
        APLUSB_TO_D                 ; D = ARRAY + 2p'
        SWAP_AB                     ; A = ARRAY + p', B = p'
        LDNX_AB halt                ; A = 6
        SKPNX_A_GRT_B               ; p' < 6: keep C = mark
        COPY_AC                     ; p' = 6: C = 6, so the JMP_C below lands on halt
        SWAP_BD                     ; B = ARRAY + 2p', D = p'
        SWAP_AB                     ; A = ARRAY + 2p'
        JMP_C
